"""bench/bench_pose_errors.py (issue 40, direction 5): its settings are captures the suite accepts,
and its table counts every realization, a failed one with its reason."""
from __future__ import annotations

from types import SimpleNamespace

from bench import bench_pose_errors as bpe


def test_settings_are_valid_captures_and_failures_are_counted_with_their_reason() -> None:
    for markers in bpe.MARKERS:
        for position, attitude in bpe.SETTINGS:
            c = bpe.capture_of(position, attitude, markers)
            assert (c.report_position_sigma, c.report_attitude_sigma, c.gcp_markers) == (position, attitude, markers)
    args = SimpleNamespace(scenarios=["one_plant"], methods=["egp"], realizations=2, models="")
    records = {}
    for markers in bpe.MARKERS:
        for position, attitude in bpe.SETTINGS:
            records[("one_plant", "egp", markers, position, attitude, 0)] = {
                "per_realization": [{"chamfer": 3.0, "chamfer_shape": 1.0}]}
            records[("one_plant", "egp", markers, position, attitude, 1)] = {
                "per_realization": [{"chamfer": None, "error": "RECONSTRUCTION_FAILED", "error_msg": "no pair"}]}
    cells = bpe.cells_of(records, args)
    c = cells["one_plant/egp/4/0.02/0.5"]
    assert (c["map"]["n"], c["map"]["failed"], c["registration"]["mean"]) == (1, 1, 2.0)
    assert c["failures"] == ["no pair"]
    md = bpe.markdown({"machine": "m", "date": "d", "realizations": 2, "cells": cells})
    assert "| one_plant | egp | 0 | 0.05 | 0.5 | 3.00 (n=1, 1 failed) | 1.00 (n=1, 1 failed) | 2.00 (n=1, 1 failed) |" in md
