# Two commands set everything up on a fresh machine: `make report` and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: report test test-slow lint docs check clean-venv
DOCS_STAMP := $(VENV)/.installed-docs

$(STAMP): pyproject.toml constraints.txt
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "error: $(PYTHON) not found (set PYTHON=...)"; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade "pip==25.3"
	$(BIN)/python -m pip install --quiet -c constraints.txt -e ".[test]"
	touch $(STAMP)

# `make report`: run the nightly campaign (`make report QUICK=1`: the smoke campaign), store the
# seed's comparison table beside the run (seed_table.json), build the HTML and PDF reports into
# reports/<run-id>/ against the previous run of the same campaign (if any), point reports/latest at
# them (a copy where symlinks fail) and print the HTML file's path last.  `mbh warm-up` first
# compiles the in-house kernels and loops on every core (its lines go to stderr).
REPORT_CAMPAIGN = $(if $(QUICK),smoke,nightly)
SEED_REPEATS = $(if $(QUICK),1,3)

report: $(STAMP)
	@$(BIN)/mbh warm-up >&2
	@set -e; \
	ran=$$($(BIN)/mbh run $(REPORT_CAMPAIGN)); echo "$$ran"; \
	run=$$(printf '%s\n' "$$ran" | sed -n 's/^run \([^:]*\):.*/\1/p'); \
	folder=$$(printf '%s\n' "$$ran" | sed -n 's/^path //p'); \
	test -n "$$run" && test -d "$$folder" || { echo "make report: no run id in mbh run's output" >&2; exit 1; }; \
	$(BIN)/mbh seed-table --json --repeats $(SEED_REPEATS) > "$$folder/.seed_table.json.tmp"; \
	mv "$$folder/.seed_table.json.tmp" "$$folder/seed_table.json"; \
	$(BIN)/mbh report "$$run" --against previous --format html,pdf --out "reports/$$run" >/dev/null; \
	rm -rf reports/latest; \
	ln -s "$$run" reports/latest 2>/dev/null || cp -R "reports/$$run" reports/latest; \
	echo "$(CURDIR)/reports/$$run/report.html"

# The suites run on every core (pytest-xdist), a test file's tests on one worker (--dist loadfile:
# module fixtures run once); TEST_WORKERS=1 runs them in one process.  `mbh warm-up` first
# compiles the in-house kernels and loops on every core (minutes once per machine and version of
# the kernels, seconds after), so the workers load them instead of compiling them in turn.
TEST_WORKERS ?= auto
XDIST = $(if $(filter 1,$(TEST_WORKERS)),-p no:xdist,-n $(TEST_WORKERS) --dist loadfile)

test: $(STAMP)
	$(BIN)/mbh warm-up
	$(BIN)/python -m pytest $(XDIST)

test-slow: $(STAMP)
	$(BIN)/mbh warm-up
	$(BIN)/python -m pytest -m slow $(XDIST)

# `make lint`: Ruff with the rules of pyproject.toml ([tool.ruff]) over the whole repository.
lint: $(STAMP)
	$(BIN)/ruff check .

# `make docs`: install the docs extra into .venv, then build docs/ strictly (a broken link or a
# missing page fails) into site/.
$(DOCS_STAMP): $(STAMP) pyproject.toml constraints.txt
	$(BIN)/python -m pip install --quiet -c constraints.txt -e ".[test,docs]"
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	$(BIN)/mkdocs build --strict --site-dir site

clean-venv:
	rm -rf $(VENV)
