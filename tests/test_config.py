"""Tests of the estimator configuration: defaults, YAML, overrides, errors that name the key."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from pydantic import ValidationError

from cldet.config import CldetConfig, config_to_dict, load_config
from cldet.errors import ConfigError


def test_defaults() -> None:
    cfg = load_config()
    assert cfg == CldetConfig()
    assert cfg.method == "track"
    assert cfg.clustering.eps_m == 1.0 and cfg.clustering.min_samples == 1
    assert cfg.bias.along_ray_m == 0.0 and cfg.bias.z_m == 0.0
    assert cfg.tracking.fallback_position == (0.734, -9.739, 33.353)


def test_yaml_then_overrides(tmp_path: Path) -> None:
    path = tmp_path / "cfg.yaml"
    path.write_text("method: cl-det\nclustering:\n  eps_m: 0.8\nbias:\n  z_m: 0.15\n")
    cfg = load_config(path)
    assert cfg.method == "cl-det"
    assert cfg.clustering.eps_m == 0.8
    assert cfg.clustering.min_samples == 1  # untouched keys keep their defaults
    assert cfg.bias.z_m == 0.15
    cfg2 = load_config(path, overrides={"clustering": {"min_samples": 2}, "method": "track"})
    assert cfg2.clustering.eps_m == 0.8 and cfg2.clustering.min_samples == 2
    assert cfg2.method == "track"


def test_empty_yaml_is_defaults(tmp_path: Path) -> None:
    path = tmp_path / "empty.yaml"
    path.write_text("")
    assert load_config(path) == CldetConfig()


def test_misspelt_key_names_file_and_key(tmp_path: Path) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text("tracking:\n  gate_chi: 9.0\n")
    with pytest.raises(ConfigError, match=r"bad\.yaml.*unknown key 'tracking\.gate_chi'"):
        load_config(path)
    with pytest.raises(ConfigError, match=r"unknown key 'clusterng'"):
        load_config(overrides={"clusterng": {"eps_m": 1.0}})


def test_bad_value_names_key_and_value() -> None:
    with pytest.raises(ConfigError, match=r"clustering\.eps_m = -1"):
        load_config(overrides={"clustering": {"eps_m": -1}})
    with pytest.raises(ConfigError, match=r"method = 'dbscan'"):
        load_config(overrides={"method": "dbscan"})


def test_bad_files(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read config file"):
        load_config(tmp_path / "missing.yaml")
    notyaml = tmp_path / "broken.yaml"
    notyaml.write_text("tracking: [unclosed\n")
    with pytest.raises(ConfigError, match=r"broken\.yaml is not valid YAML"):
        load_config(notyaml)
    alist = tmp_path / "list.yaml"
    alist.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="must hold a mapping"):
        load_config(alist)


def test_frozen() -> None:
    cfg = load_config()
    with pytest.raises(ValidationError):
        cfg.clustering.eps_m = 3.0  # type: ignore[misc]


def test_config_to_dict_round_trips_through_json() -> None:
    cfg = load_config(overrides={"bias": {"along_ray_m": 0.1}, "frames": {"scan_offset_s": 0.02}})
    data = json.loads(json.dumps(config_to_dict(cfg)))
    assert data["bias"]["along_ray_m"] == 0.1
    assert data["tracking"]["fallback_position"] == [0.734, -9.739, 33.353]
    assert CldetConfig.model_validate(data) == cfg


def test_field_of_view_cut_settings_are_validated() -> None:
    cfg = load_config(overrides={"tracking": {"fov_cut_m": 0.0, "fov_bottom_deg": -7.0}})
    assert cfg.tracking.fov_cut_m == 0.0
    with pytest.raises(ConfigError, match="fov_bottom_deg"):
        load_config(overrides={"tracking": {"fov_bottom_deg": 5.0}})


def test_point_times_keeps_the_former_bool_values(tmp_path: Path) -> None:
    # the switch was a bool (true: dated in the tracker and the smoother); a YAML written then
    # still loads, with the same meaning
    path = tmp_path / "cfg.yaml"
    path.write_text("frames:\n  point_times: true\n")
    assert load_config(path).frames.point_times == "track"
    assert load_config(overrides={"frames": {"point_times": False}}).frames.point_times == "off"
    assert load_config().frames.point_times == "fit"
    with pytest.raises(ConfigError, match=r"frames\.point_times.*'off', 'fit' or 'track'"):
        load_config(overrides={"frames": {"point_times": "sometimes"}})
