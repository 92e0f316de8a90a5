# The two set-up commands: `make demo` (the main job on the bundled sample recording) and `make test`.
VENV    ?= .venv
PYTHON  ?= python3
PY      := $(VENV)/bin/python
STAMP   := $(VENV)/.hac_installed

# DDS never leaves this machine, and runs get their own domain so they never hear each other:
# 90..99 here (demo), while each test process locks one of 10..89 (test/conftest.py).
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST
export ROS_DOMAIN_ID ?= $(shell echo $$(( $$$$ % 10 + 90 )))

.PHONY: all install lint test demo docs bench bags clean

all: test

$(STAMP): setup.py setup.cfg package.xml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[ros,dev,video]'
	touch $(STAMP)

install: $(STAMP)

lint: $(STAMP)
	$(PY) -m ruff check hac_ros msg_adapters test bench launch
	$(PY) -m mypy

test: lint
	$(PY) -m pytest -q

demo: $(STAMP)
	$(PY) -m hac_ros.cli demo

# the docs' generated blocks (the reason table, ...) from the code: test/regen_docs.py
docs: $(STAMP)
	$(PY) test/regen_docs.py

bench: $(STAMP)
	$(PY) bench/accuracy.py
	$(PY) bench/variants.py
	$(PY) bench/steep_views.py
	$(PY) bench/core_speed.py
	$(PY) bench/replay_throughput.py
	$(PY) bench/batch_throughput.py
	$(PY) bench/node_latency.py
	$(PY) bench/node_memory.py
	$(PY) bench/people_speed.py
	$(PY) bench/people_accuracy.py
	$(PY) bench/people_real.py
	$(PY) bench/video.py accuracy
	$(PY) bench/video.py speed

clean:
	rm -rf out build install log .pytest_cache
