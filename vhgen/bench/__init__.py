"""Benchmarks that need the whole stack (GL, the pipeline): sensor fidelity scenes and
`vhgen bench fidelity`. Nothing below this layer imports it."""
