# Two commands on a fresh machine: `make demo` and `make test`. Each does its own set-up.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-dev

.PHONY: demo test lint bench bench-io bench-laser bench-camera bench-fusion bench-imu bench-traffic bench-baselines clean install

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# Reinstall when the dependency list changes.
$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

install: $(STAMP)

test: $(STAMP)
	$(BIN)/python -m pytest -n 2 --dist loadfile -q

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks

demo: $(STAMP)
	$(BIN)/python -m fusiontrack demo -o out/demo

# Benchmarks print tables; each group takes a few minutes on 2 cores. `make bench` runs them all but the
# Stone Soup comparison, which needs an optional extra (`make bench-baselines` installs it).
bench: bench-io bench-laser bench-camera bench-fusion bench-imu bench-traffic

bench-io: $(STAMP)
	$(BIN)/python benchmarks/read_throughput.py
	$(BIN)/python benchmarks/simulate.py

bench-laser: $(STAMP)
	$(BIN)/python benchmarks/laser_detection.py
	$(BIN)/python benchmarks/tracking_step.py
	$(BIN)/python benchmarks/laser_people.py

bench-camera: $(STAMP)
	$(BIN)/python benchmarks/camera.py
	$(BIN)/python benchmarks/camera_people.py
	$(BIN)/python benchmarks/appearance.py

bench-fusion: $(STAMP)
	$(BIN)/python benchmarks/bias.py
	$(BIN)/python benchmarks/fusion.py

bench-imu: $(STAMP)
	$(BIN)/python benchmarks/pdr_steps.py
	$(BIN)/python benchmarks/rgbd_compressive.py
	$(BIN)/python benchmarks/pdr.py

bench-traffic: $(STAMP)
	$(BIN)/python benchmarks/laser_vehicles.py
	$(BIN)/python benchmarks/camera_vehicles.py
	$(BIN)/python benchmarks/scene.py
	$(BIN)/python benchmarks/traffic.py

bench-baselines: $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[dev,stonesoup]"
	$(BIN)/python benchmarks/laser_baselines.py

clean:
	rm -rf $(VENV) out .pytest_cache build src/*.egg-info
