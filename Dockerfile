# vhgen worker/driver image: Debian 12, Python 3.11, Mesa EGL + OSMesa, vhgen, MPFB2 assets.
# On NVIDIA GPUs run with the NVIDIA container toolkit and graphics capability so the
# driver's EGL is mounted:  docker run --gpus all -e NVIDIA_DRIVER_CAPABILITIES=graphics,compute,utility ...
# vhgen logs GL_RENDERER at start; llvmpipe there means the GPU was not reached.
FROM debian:12-slim

ENV DEBIAN_FRONTEND=noninteractive \
    VHGEN_HOME=/opt/vhgen-cache \
    PATH=/opt/vhgen/.venv/bin:$PATH

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
RUN bash scripts/setup.sh
# KubeRay starts Ray through a login shell (bash -l), whose /etc/profile resets PATH: put
# the virtualenv back for `ray start` and the job's `python`
RUN echo 'export PATH=/opt/vhgen/.venv/bin:$PATH' > /etc/profile.d/vhgen.sh

ENTRYPOINT ["vhgen"]
CMD ["generate", "configs/scenes/default.yaml", "--out", "/data/default.zarr"]
