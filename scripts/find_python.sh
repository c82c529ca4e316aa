#!/usr/bin/env bash
# Print the path of a Python >= 3.12 interpreter (lerobot 0.6.1 needs it): PATH first, then pyenv.
# 3.12 is preferred: it is the version the whole stack (torch, numba, robosuite) was verified on.
set -u
ok() { "$1" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 12) else 1)' 2>/dev/null; }
for name in python3.12 python3 python python3.13; do
  p=$(command -v "$name" 2>/dev/null) && ok "$p" && { echo "$p"; exit 0; }
done
root=${PYENV_ROOT:-$HOME/.pyenv}
for p in $(ls -d "$root"/versions/3.12*/bin/python3 2>/dev/null | sort -rV) \
         $(ls -d "$root"/versions/3.1[3-9]*/bin/python3 2>/dev/null | sort -rV); do
  ok "$p" && { echo "$p"; exit 0; }
done
echo "error: no Python >= 3.12 found on PATH or in $root/versions (lerobot 0.6.1 requires it)." >&2
echo "Install one (e.g. 'pyenv install 3.12') or put it on PATH, then re-run make." >&2
exit 1
