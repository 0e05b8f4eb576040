# Entry points for people: `make demo`, `make test` (everything, what CI runs) and `make check`
# (the fast subset for everyday work: no e2e, no slow modules; markers in test/conftest.py).
# All bootstrap .venv first (idempotent; seconds on the second run).
PY := .venv/bin/python

.PHONY: bootstrap demo test check
bootstrap:
	@bash scripts/bootstrap.sh

demo: bootstrap
	.venv/bin/defgg-demo

# Two workers (pytest-xdist), a test file per worker at a time: each worker has its own ROS domain
# (test/conftest.py), and the e2e cells leave a core mostly idle, so the suite takes ~2/3 of the serial
# time on 2 cores. TEST_WORKERS=0 runs it in this process, serially. Files are taken heaviest first
# (test/conftest.py's heaviest_files_first; --no-loadscope-reorder keeps that order).
# The 25 slowest tests are listed at the end: where a slow machine's (or CI's) time went.
TEST_WORKERS ?= 2
test: bootstrap
	$(PY) -m pytest -q -p no:cacheprovider -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder --durations=25 test

check: bootstrap
	$(PY) -m pytest -q -p no:cacheprovider -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder -m "not e2e and not slow" test
