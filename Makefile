# Convenience targets; each first runs the idempotent set-up (scripts/setup.sh prints the venv's python).
.PHONY: test demo bench bench-quick

test:
	bash scripts/test.sh

demo:
	bash scripts/demo.sh

# Full benchmark suite (hours): tables and plots in benchmarks/out/, summary in benchmarks/out/SUMMARY.md
bench:
	py=$$(bash scripts/setup.sh --bench | tail -n 1) && $$py -m fem_squeal.cli bench

# Smoke version of every benchmark (minutes)
bench-quick:
	py=$$(bash scripts/setup.sh --bench | tail -n 1) && $$py -m fem_squeal.cli bench --quick
