# The set-up every *_on_device.sh script shares on a lent GPU machine (sourced, not run): unpack
# the carried GL libraries (.gl/*.deb), install the carried wheels (.whl/) into /tmp/site, point
# EGL at NVIDIA's vendor file and say which GPU is there. tools/pretrain_on_device.sh's header
# says how to prepare .gl and .whl.
for f in .gl/*.deb; do dpkg -x "$f" /; done
ldconfig
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
  --target /tmp/site .whl/*.whl
# PYGLET_HEADLESS: pyrender imports pyglet's window module, which otherwise needs X11 libraries
export PYTHONPATH=/tmp/site:$PWD PYOPENGL_PLATFORM=egl PYGLET_HEADLESS=1 PYTHONUNBUFFERED=1
vendor=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
if [ -f "$vendor" ]; then export __EGL_VENDOR_LIBRARY_FILENAMES=$vendor; fi
nvidia-smi -L || true
