# Fresh machine: `make demo` and `make test` each create .venv with pip and install the project.
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp

export HF_HUB_OFFLINE := 1
export HF_DATASETS_OFFLINE := 1
export MUJOCO_GL ?= egl
export PYOPENGL_PLATFORM ?= egl
# One BLAS thread: the per-frame GP mat-vecs are tiny, and threaded BLAS on a shared 2-core
# machine made fitting 10-30x slower (train.py --threads sets torch's own thread count).
export OMP_NUM_THREADS ?= 1
export OPENBLAS_NUM_THREADS ?= 1

.PHONY: demo test lint bench install clean

# e.g. `make test TORCH_INDEX=https://download.pytorch.org/whl/cpu`: torch from that index first
# (the CPU-only build), then the project's extras keep it.
TORCH_INDEX ?=

install: $(STAMP)

$(STAMP): pyproject.toml
	@test -x $(PY) || python3 -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(if $(TORCH_INDEX),$(PY) -m pip install --quiet torch --index-url $(TORCH_INDEX))
	$(PY) -m pip install --quiet -e '.[test]'
	# compile the env's numba kernels once into the cache, before test workers or the demo start
	$(PY) -m handover_env.envs.warmup
	@touch $(STAMP)

demo: $(STAMP)
	$(PY) -m handover_eval.cli.demo

# pytest-xdist: a test file per worker process (module fixtures stay shared), 2 = CI's cores
TEST_WORKERS ?= 2

test: lint
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile

lint: $(STAMP)
	$(PY) -m ruff check .

bench: $(STAMP)
	$(PY) bench/run_all.py

clean:
	rm -rf $(VENV) .pytest_cache build *.egg-info
