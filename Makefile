# Two entry points for people: `make demo` and `make test`. Both bootstrap
# .venv first (idempotent; seconds on the second run).
PY := .venv/bin/python

.PHONY: bootstrap demo test
bootstrap:
	@bash scripts/bootstrap.sh

demo: bootstrap
	.venv/bin/defgg-demo

test: bootstrap
	$(PY) -m pytest -q -p no:cacheprovider test
