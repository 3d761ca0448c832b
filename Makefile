# vp-suite: EGP-VP view planning for camera drones over a noisy corn field (ROS 2 Jazzy).
# `make run` and `make test` set everything up on a fresh Debian 12 / Python 3.11 machine.
SHELL := /bin/bash
.DEFAULT_GOAL := help

# DDS stays on this machine; every run gets its own domain unless one is given.
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST
export ROS_DOMAIN_ID ?= $(shell echo $$(( $$$$ % 200 + 10 )))
export PYOPENGL_PLATFORM ?= egl

SCENARIO ?= one_plant
# LAYOUT=path/to/field.yaml: a layout file instead of a built-in SCENARIO (README "Your own field")
LAYOUT   ?=
SCENE_ARG = $(or $(LAYOUT),$(SCENARIO))
SCENE_TAG = $(basename $(notdir $(SCENE_ARG)))
METHOD   ?= egp
CAMERAS  ?= 4
DRONES   ?= $(CAMERAS)
# make run ROUNDS=2 CAMERAS=N CAMERAS2=M: a second sortie of M given the first (docs/planner.md "A second sortie")
ROUNDS   ?= 1
CAMERAS2 ?= 0
EVALS    ?= 100
SEED     ?= 0
REWARD   ?=
# make run again: the earlier run in OUT is moved to OUT-<time> first (README "Two commands")
OUT      ?= out/$(SCENE_TAG)-$(METHOD)-$(CAMERAS)cams-seed$(SEED)
# OVERWRITE=1: make plan / make recon replace the plan / reconstruction OUT holds (else refused)
OVERWRITE ?=
MODELS   ?=
PLAN     ?= $(OUT)/plan.json
RECON_ARGS ?=
RUN_ARGS ?=
IMAGES   ?=
PRIOR    ?=
# make test TEST_WORKERS=K: the suite's files on K pytest workers (each test's own processes run 1 thread;
# the tests mostly compute, so more workers than cores only slows each test); the heaviest folders are
# collected first and the many short unit tests last, so that the two workers end together
TEST_WORKERS ?= 2
# make view RUN=out/<run folder> [PORT=8080]: the run's recording in the browser (README "Looking at a plan")
RUN      ?= $(OUT)
PORT     ?= 8080

ENV := . .venv/bin/activate && . install/setup.bash &&

.PHONY: help setup test run plan recon score view bench docs clean
help:
	@echo "make setup | test | run | plan | recon | score | view | bench | docs | clean   (see README.md)"

setup:
	@tools/setup.sh

test: setup
	@$(ENV) python -m pytest -q -p no:cacheprovider -n $(TEST_WORKERS) --dist loadfile --durations=20 \
	  src/vp_recon/test tests src/vp_planner/test src/vp_scene/test

run: setup
	@$(ENV) python tools/run_suite.py --scenario $(SCENE_ARG) --method $(METHOD) --cameras $(CAMERAS) \
	  --evals $(EVALS) --seed $(SEED) --out $(OUT) --drones $(DRONES) $(if $(MODELS),--models $(MODELS)) \
	  $(if $(REWARD),--reward $(REWARD)) --rounds $(ROUNDS) --cameras2 $(CAMERAS2) $(RUN_ARGS)

plan: setup
	@$(ENV) python -m vp_planner.cli --scenario $(SCENE_ARG) --method $(METHOD) --cameras $(CAMERAS) \
	  --evals $(EVALS) --seed $(SEED) --out $(OUT) $(if $(MODELS),--models $(MODELS)) $(if $(REWARD),--reward $(REWARD)) \
	  $(if $(OVERWRITE),--overwrite)

# make recon IMAGES=DIR [PRIOR=plan.json]: a flight folder (README "From a real flight") into
# DIR-recon (or OUT=... given on the command line); without IMAGES: render and reconstruct PLAN
recon: setup
	@$(ENV) python -m vp_recon.cli $(if $(IMAGES),--images $(IMAGES) --out $(if $(filter file,$(origin OUT)),$(patsubst %/,%,$(IMAGES))-recon,$(OUT)) $(if $(PRIOR),--prior $(PRIOR)),--plan $(PLAN) --out $(OUT)) $(if $(OVERWRITE),--overwrite) $(RECON_ARGS)

score: setup
	@$(ENV) python -m vp_planner.cli score --plan $(PLAN) $(if $(REWARD),--reward $(REWARD))

view: setup
	@$(ENV) python -m vp_recon.viewer $(RUN) --port $(PORT)

bench: setup
	@$(ENV) python -m bench.table1 $(if $(MODELS),--models $(MODELS))

# docs/results.md and docs/history_results.md from the files under results/, and the generated blocks of
# README.md and docs/ from the code (docs/development.md); never edited by hand
docs: setup
	@$(ENV) python -m bench.docs && python tools/doc_tables.py

clean:
	rm -rf build install log
