"""The cluster path for real: the KubeRay RayJob manifest read against KubeRay's RayJob
schema (offline), and `vhgen generate --address` / `ray job submit` against a Ray head
this test starts (and stops) itself."""

from __future__ import annotations

import os
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parent.parent

# Field names of KubeRay's ray.io/v1 API, from ray-project/kuberay
# ray-operator/apis/ray/v1/rayjob_types.go (RayJobSpec) and raycluster_types.go
# (RayClusterSpec, HeadGroupSpec, WorkerGroupSpec), the Go types that controller-gen turns
# into config/crd/bases/ray.io_rayjobs.yaml. "required" = json tag without omitempty.
RAYJOB_SPEC = {
    "activeDeadlineSeconds", "backoffLimit", "rayClusterSpec", "submitterPodTemplate",
    "metadata", "clusterSelector", "submitterConfig", "managedBy", "deletionStrategy",
    "entrypoint", "runtimeEnvYAML", "jobId", "submissionMode", "entrypointResources",
    "entrypointNumCpus", "entrypointNumGpus", "ttlSecondsAfterFinished",
    "shutdownAfterJobFinishes", "suspend", "schedule",
}
RAYCLUSTER_SPEC = {"headGroupSpec", "workerGroupSpecs", "rayVersion", "enableInTreeAutoscaling",
                   "autoscalerOptions", "headServiceAnnotations", "suspend"}
RAYCLUSTER_REQUIRED = {"headGroupSpec"}
HEAD_GROUP = {"serviceType", "headService", "enableIngress", "rayStartParams", "template"}
HEAD_REQUIRED = {"rayStartParams", "template"}
WORKER_GROUP = {"groupName", "replicas", "minReplicas", "maxReplicas", "numOfHosts",
                "rayStartParams", "template", "scaleStrategy"}
WORKER_REQUIRED = {"groupName", "minReplicas", "maxReplicas", "rayStartParams", "template"}
# Kubernetes core/v1 Container fields used in pod templates (k8s.io/api/core/v1 types.go)
CONTAINER = {"name", "image", "command", "args", "workingDir", "ports", "envFrom", "env",
             "resources", "volumeMounts", "volumeDevices", "livenessProbe", "readinessProbe",
             "startupProbe", "lifecycle", "terminationMessagePath", "imagePullPolicy",
             "securityContext", "stdin", "tty"}

MANIFEST = REPO / "cluster" / "rayjob.yaml"


def _docs() -> dict[str, dict]:
    docs = [d for d in yaml.safe_load_all(MANIFEST.read_text()) if d]
    return {d["kind"]: d for d in docs}


def _check_keys(obj: dict, allowed: set[str], required: set[str], where: str) -> None:
    assert isinstance(obj, dict), where
    assert not set(obj) - allowed, f"{where}: unknown fields {sorted(set(obj) - allowed)}"
    assert not required - set(obj), f"{where}: missing {sorted(required - set(obj))}"


def _check_pod(template: dict, where: str, mount: str) -> list[dict]:
    spec = template["spec"]
    containers = spec["containers"]
    claims = {v["name"]: v["persistentVolumeClaim"]["claimName"] for v in spec["volumes"]
              if "persistentVolumeClaim" in v}
    for c in containers:
        _check_keys(c, CONTAINER, {"name"}, f"{where}.containers[{c.get('name')}]")
        assert c["image"] == "ghcr.io/vhgen/vhgen:latest"
        mounts = {m["mountPath"]: m["name"] for m in c["volumeMounts"]}
        assert claims.get(mounts.get(mount)) == "vhgen-datasets", f"{where}: no shared volume"
    return containers


def test_rayjob_manifest_matches_the_kuberay_schema():
    docs = _docs()
    job = docs["RayJob"]
    assert job["apiVersion"] == "ray.io/v1" and job["kind"] == "RayJob"
    assert job["metadata"]["name"]
    spec = job["spec"]
    _check_keys(spec, RAYJOB_SPEC, {"entrypoint", "rayClusterSpec"}, "spec")
    assert isinstance(spec["shutdownAfterJobFinishes"], bool)
    rc = spec["rayClusterSpec"]
    _check_keys(rc, RAYCLUSTER_SPEC, RAYCLUSTER_REQUIRED, "spec.rayClusterSpec")
    head = rc["headGroupSpec"]
    _check_keys(head, HEAD_GROUP, HEAD_REQUIRED, "headGroupSpec")
    # rayStartParams is map[string]string: every value must be a YAML string
    assert all(isinstance(v, str) for v in head["rayStartParams"].values())
    argv = shlex.split(spec["entrypoint"])
    out = Path(argv[argv.index("--out") + 1])
    _check_pod(head["template"], "head", "/mnt/datasets")
    assert out.parent == Path("/mnt/datasets")  # the driver merges on the shared volume
    assert rc["rayVersion"] == __import__("ray").__version__
    (group,) = rc["workerGroupSpecs"]
    _check_keys(group, WORKER_GROUP, WORKER_REQUIRED, "workerGroupSpecs[0]")
    assert all(isinstance(v, str) for v in group["rayStartParams"].values())
    assert 0 <= group["minReplicas"] <= group["replicas"] <= group["maxReplicas"]
    (worker,) = _check_pod(group["template"], "worker", "/mnt/datasets")
    for kind in ("requests", "limits"):
        assert worker["resources"][kind]["nvidia.com/gpu"] >= 1
    env = {e["name"]: e["value"] for e in worker["env"]}
    assert "graphics" in env["NVIDIA_DRIVER_CAPABILITIES"]  # the driver's EGL gets mounted
    pvc = docs["PersistentVolumeClaim"]
    assert pvc["metadata"]["name"] == "vhgen-datasets"
    assert pvc["spec"]["accessModes"] == ["ReadWriteMany"]  # every node writes shards


def test_rayjob_entrypoint_runs_this_repository():
    """The entrypoint's script and config exist in the image (the repository at
    /opt/vhgen, see Dockerfile) and the config asks Ray for GPUs per actor."""
    from vhgen.job_config import JobConfig

    spec = _docs()["RayJob"]["spec"]
    argv = shlex.split(spec["entrypoint"])
    assert argv[0] == "python"
    script, config = (Path(a.replace("/opt/vhgen/", str(REPO) + "/")) for a in argv[1:3])
    assert script == REPO / "jobs" / "generate.py" and script.is_file()
    assert "COPY . /opt/vhgen" in (REPO / "Dockerfile").read_text()
    cfg = JobConfig.load(config)
    assert cfg.backend == "egl" and cfg.gpus_per_worker > 0
    gpus = spec["rayClusterSpec"]["workerGroupSpecs"][0]["template"]["spec"]["containers"][0][
        "resources"]["limits"]["nvidia.com/gpu"]
    cpus = int(spec["rayClusterSpec"]["workerGroupSpecs"][0]["template"]["spec"]["containers"][0][
        "resources"]["limits"]["cpu"])
    # the actors of one worker pod fit its CPUs and GPUs
    assert cpus * cfg.gpus_per_worker <= gpus


# --- a real Ray head ---------------------------------------------------------------------

JOB = """
name: tiny
seed: 9
motions: [{m}/01_01.bvh]
sensor: kinect_v1_fast
poses: {{frame_step: 400, skip_first: 1, max_per_motion: 2}}
avatars: {{count: 1}}
output: {{frames_per_shard: 1}}
render: {{backend: osmesa}}
num_workers: 2
"""


def _free_ports(n: int) -> list[int]:
    socks = [socket.socket() for _ in range(n)]
    for s in socks:
        s.bind(("127.0.0.1", 0))
    ports = [s.getsockname()[1] for s in socks]
    for s in socks:
        s.close()
    return ports


def _own_processes(tag: str) -> list[int]:
    """Pids whose command line mentions our private temp dir (only processes we started)."""
    pids = []
    for p in Path("/proc").iterdir():
        if p.name.isdigit():
            try:
                if tag in (p / "cmdline").read_bytes().decode(errors="replace"):
                    pids.append(int(p.name))
            except OSError:
                pass
    return [p for p in pids if p != os.getpid()]


@pytest.fixture(scope="module")
def ray_head():
    """`ray start --head --block` on free ports and a private temp dir; stopped by killing
    its process group (never `ray stop`, which would stop every Ray on the machine)."""
    tmp = tempfile.mkdtemp(prefix="vr", dir="/tmp")  # short: Ray's socket paths are long
    gcs, dash, client, agent, agent_grpc, metrics, rt_env = _free_ports(7)
    env = dict(os.environ, RAY_AUTH_MODE="disabled",  # Ray 2.60 enables token auth otherwise
               PATH=f"{Path(sys.executable).parent}:{os.environ['PATH']}")
    cmd = [str(Path(sys.executable).parent / "ray"), "start", "--head", "--block",
           "--num-cpus", "2", "--disable-usage-stats", f"--temp-dir={tmp}",
           f"--port={gcs}", f"--dashboard-port={dash}", "--dashboard-host=127.0.0.1",
           f"--ray-client-server-port={client}", f"--dashboard-agent-listen-port={agent}",
           f"--dashboard-agent-grpc-port={agent_grpc}", f"--metrics-export-port={metrics}",
           f"--runtime-env-agent-port={rt_env}"]
    proc = subprocess.Popen(cmd, env=env, start_new_session=True, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.time() + 60
        while True:
            try:
                socket.create_connection(("127.0.0.1", dash), timeout=1).close()
                break
            except OSError:
                if proc.poll() is not None or time.time() > deadline:
                    pytest.fail(f"ray start failed: {proc.stdout.read() if proc.stdout else ''}")
                time.sleep(0.5)
        yield {"address": f"127.0.0.1:{gcs}", "dashboard": f"http://127.0.0.1:{dash}",
               "env": env}
    finally:
        os.killpg(proc.pid, signal.SIGTERM)
        try:  # `ray start --block` took the whole 30 s it was once given to exit on SIGTERM
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
        time.sleep(1)
        for pid in _own_processes(tmp):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        leftover = _own_processes(tmp)
        shutil.rmtree(tmp, ignore_errors=True)
        assert not leftover, f"Ray processes left running: {leftover}"


def _job(tmp: Path, shared: Path) -> Path:
    p = tmp / "tiny.yaml"
    p.write_text(JOB.format(m=shared))
    return p


def _arrays(store: Path) -> dict[str, bytes]:
    return {str(p.relative_to(store)): p.read_bytes() for p in sorted(store.rglob("*"))
            if p.is_file() and p.parts[len(store.parts)] in ("depth", "labels")}


@pytest.mark.slow
def test_generate_and_job_submit_on_a_ray_head(ray_head, tmp_path, shared_mocap, asset_dir):
    from vhgen.store.inspect import inspect_store

    cfg = _job(tmp_path, shared_mocap)
    vhgen = Path(sys.executable).parent / "vhgen"
    a = tmp_path / "address.zarr"
    res = subprocess.run([str(vhgen), "generate", str(cfg), "--out", str(a),
                          "--address", ray_head["address"]], env=ray_head["env"],
                         capture_output=True, text=True, timeout=180)
    assert res.returncode == 0, res.stderr[-3000:]
    assert "wrote 2 frames" in res.stdout
    b = tmp_path / "submitted.zarr"
    res = subprocess.run(
        [str(Path(sys.executable).parent / "ray"), "job", "submit", "--address",
         ray_head["dashboard"], "--", "python", str(REPO / "jobs" / "generate.py"), str(cfg),
         "--out", str(b)], env=ray_head["env"], capture_output=True, text=True, timeout=180)
    assert res.returncode == 0, (res.stdout + res.stderr)[-3000:]
    assert "succeeded" in res.stdout and "wrote 2 frames" in res.stdout
    for store in (a, b):
        rep = inspect_store(store)
        assert rep.ok and rep.num_frames == 2, rep.defects
    # the same config gives the same bytes through either path
    assert _arrays(a) == _arrays(b) and len(_arrays(a)) == 6  # 2 shards x 2 arrays + metadata
