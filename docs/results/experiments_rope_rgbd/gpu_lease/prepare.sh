#!/bin/bash
# Builds .dev/ (git-ignored through .git/info/exclude), what a device lease carries beside the working tree:
# the wheels of the lerobot stack the device image lacks, robosuite without the robot and gripper meshes the
# rope scene never loads (530 MB -> 5 MB; the rope RGB-D frames render byte-identical with it), and a PyAV
# stand-in (its 40 MB wheel does not fit the 64 MiB a call carries; online training decodes no video).
# .gl/ holds the GL/EGL loader packages the device image lacks (Debian's, unpacked there by run.sh).
# Run from the repo root on a machine with `make install` done.
set -euo pipefail
for d in /.dev/ /.gl/; do grep -qx "$d" .git/info/exclude || echo "$d" >> .git/info/exclude; done
rm -rf .gl && mkdir -p .gl /tmp/amd64/partial
o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
apt-get $o update > /dev/null
(cd .gl && apt-get $o download libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
rm -rf .dev && mkdir -p .dev/whl .dev/site .dev/stub/av .dev/stub/av-15.1.0.dist-info
P="--platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_17_x86_64"
.venv/bin/python -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
    $P --platform any -d .dev/whl lerobot==0.6.1 mujoco==3.3.7 datasets==4.8.5 gymnasium==1.4.0 \
    PyOpenGL==3.1.10 glfw==2.11.0 draccus==0.11.6 mergedeep==1.3.4 dill==0.4.1 multiprocess==0.70.19 \
    Farama-Notifications==0.0.6 termcolor==3.3.0
cp -r .venv/lib/python3.12/site-packages/robosuite .dev/site/
(cd .dev/site/robosuite && rm -rf demos models/assets/{robots,grippers,bullet_data,bases} \
    && find . -name __pycache__ -prune -exec rm -rf {} + \
    && cd models/assets/textures \
    && find . -maxdepth 1 -type f ! -name light-gray-floor-tile.png ! -name ceramic.png \
        ! -name steel-brushed.png ! -name light-gray-plaster.png -delete)
cat > .dev/stub/av/__init__.py <<'PY'
"""PyAV stand-in for device runs: lerobot imports av at module level; online training never opens a video."""


class _Any:
    def __getattr__(self, name):
        return self

    def __call__(self, *args, **kwargs):
        raise RuntimeError("PyAV is not installed on this machine")

    def __or__(self, other):
        return self

    __ror__ = __or__


_ANY = _Any()
library_versions = {"libavutil": (0, 0, 0)}


def __getattr__(name):
    return _ANY
PY
printf 'Metadata-Version: 2.1\nName: av\nVersion: 15.1.0\n' > .dev/stub/av-15.1.0.dist-info/METADATA
du -sh .dev .gl
