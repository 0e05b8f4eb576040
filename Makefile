# Entry points for people: `make demo`, `make test` (everything, what CI runs) and `make check`
# (the fast subset for everyday work: no e2e, no slow modules; markers in test/conftest.py).
# All bootstrap .venv first (idempotent; seconds on the second run).
PY := .venv/bin/python

.PHONY: bootstrap demo test check
bootstrap:
	@bash scripts/bootstrap.sh

demo: bootstrap
	.venv/bin/defgg-demo

test: bootstrap
	$(PY) -m pytest -q -p no:cacheprovider test

check: bootstrap
	$(PY) -m pytest -q -p no:cacheprovider -m "not e2e and not slow" test
