#!/bin/bash
# Installs PyTorch 2.9.0 (the libtorch that burn 0.22's `tch` backend, via tch/torch-sys 0.22,
# expects) into a venv, for the optional `--features tch` build (docs/training-tch.md).
# The default build, the tests and render-and-denoise never need it.
#
#   tools/install_libtorch.sh            # venv at target/torch-venv
#   TORCH_VENV=/some/dir tools/install_libtorch.sh
#
# Tries the CPU-only wheel index first (download.pytorch.org, ~200 MB), then PyPI (the Linux
# wheel there is the CUDA build: ~900 MB plus ~3-4 GB of nvidia-* libraries; it runs on CPU).
# Idempotent: an existing venv with torch 2.9.0 is kept; only the env lines are printed again.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${TORCH_VENV:-$PWD/target/torch-venv}
VERSION=2.9.0
PY=${PYTHON:-python3}

have_torch() {
    [ -x "$VENV/bin/python" ] &&
        "$VENV/bin/python" -c "import torch, sys; sys.exit(0 if torch.__version__.split('+')[0] == '$VERSION' else 1)" 2>/dev/null
}

if have_torch; then
    echo "torch $VERSION already in $VENV"
else
    if [ ! -x "$VENV/bin/python" ]; then
        mkdir -p "$(dirname "$VENV")"
        "$PY" -m venv "$VENV"
    fi
    # Reachability of the CPU index decides; a failing install there falls back to PyPI too.
    if curl -fsS --max-time 15 -o /dev/null https://download.pytorch.org/whl/cpu/torch/ 2>/dev/null &&
        "$VENV/bin/pip" install --index-url https://download.pytorch.org/whl/cpu "torch==$VERSION"; then
        echo "installed the CPU-only wheel of torch $VERSION"
    else
        echo "download.pytorch.org not reachable (or failed): installing torch $VERSION from PyPI (CUDA build, several GB)"
        "$VENV/bin/pip" install "torch==$VERSION"
    fi
    have_torch || { echo "torch $VERSION not importable from $VENV" >&2; exit 1; }
fi

LIB=$("$VENV/bin/python" -W ignore -c "import torch, os; print(os.path.join(os.path.dirname(torch.__file__), 'lib'))" 2>/dev/null)
cat <<EOF

To build and run with the LibTorch backend, in this shell:

  export LIBTORCH_USE_PYTORCH=1
  export PATH="$VENV/bin:\$PATH"
  export LD_LIBRARY_PATH="$LIB\${LD_LIBRARY_PATH:+:\$LD_LIBRARY_PATH}"
  cargo build --release --features tch
  target/release/pixguide train --backend tch ...
  cargo run --release -p denoiser --features tch --example train_step -- default 2 96 8 5 g tch

(LIBTORCH_USE_PYTORCH=1 makes torch-sys take libtorch from this venv's python instead of
downloading it; the binary needs LD_LIBRARY_PATH at run time. With a custom CARGO_TARGET_DIR,
the binary is there instead of target/. On a machine shared with other jobs, also
export OMP_NUM_THREADS=<free cores> or OMP_WAIT_POLICY=PASSIVE: LibTorch's spinning OpenMP
threads slow down badly when a core is taken; docs/training-tch.md.)
EOF
