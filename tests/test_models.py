"""Sensor and material models: presets, user files, and their errors."""

from __future__ import annotations

import numpy as np
import pytest

from optipose.errors import ConfigError
from optipose.model.material import load_material, material_presets
from optipose.model.sensor import load_sensor, sensor_presets


def test_presets_are_shipped():
    assert {"keyence-lj-x8080", "keyence-lj-x8060"} <= set(sensor_presets())
    assert {"milled-aluminium-ra1.6", "smooth-aluminium-ra0.8", "black-pla", "smooth-steel"} <= set(material_presets())


def test_lj_x8080_geometry_by_hand():
    s = load_sensor("keyence-lj-x8080")
    assert s.reference_distance == pytest.approx(0.073)
    assert (s.z_near, s.z_far) == pytest.approx((-0.0205, 0.0205))
    # straight fan through 30 mm at -20.5 and 39 mm at +20.5: half-width grows 4.5 mm per 41 mm, so the
    # apex is 15 / (4.5 / 41) = 136.7 mm before the near end
    assert s.apex_z == pytest.approx(-0.0205 - 0.015 * 41 / 4.5)
    assert np.degrees(np.arctan(s.baseline / s.reference_distance)) == pytest.approx(22.3, abs=0.1)


def test_user_sensor_preset_from_toml(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(
        "[my-sensor]\nreference_distance_mm = 100\nz_half_range_mm = 10\nwidth_near_mm = 20\n"
        "width_reference_mm = 22\nwidth_far_mm = 24\npoints_per_profile = 800\nbaseline_mm = 40\n"
    )
    s = load_sensor(path)
    assert s.name == "my-sensor" and s.points_per_profile == 800
    assert s.reference_distance == pytest.approx(0.1) and s.baseline == pytest.approx(0.04)
    assert s.laser_rays()[0].shape == (800, 3)


@pytest.mark.parametrize(
    "body, message",
    [
        ("[s]\nreference_distance_mm = 100\n", "missing"),
        (
            "[s]\nreference_distance_mm = 5\nz_half_range_mm = 10\nwidth_near_mm = 1\nwidth_reference_mm = 1\nwidth_far_mm = 2\n",
            "reference_distance",
        ),
        ("[s]\ncolour = 'red'\n", "unknown key"),
        ("[a]\nx=1\n[b]\nx=2\n", "exactly one"),
    ],
)
def test_bad_sensor_files(tmp_path, body, message):
    path = tmp_path / "bad.toml"
    path.write_text(body)
    with pytest.raises(ConfigError, match=message):
        load_sensor(path)


def test_measured_material_table_interpolates_and_drops_out(tmp_path):
    path = tmp_path / "sample.csv"
    path.write_text("aoi_deg,intensity\n0,0.8\n30,0.5\n60,0.2\n70,0.04\n")
    m = load_material(path)
    assert m.intensity(np.deg2rad([0, 15, 45, 65, 80])) == pytest.approx([0.8, 0.65, 0.35, 0.12, 0.0])
    assert np.rad2deg(m.max_aoi(0.05)) == pytest.approx(69.4, abs=0.1)  # 0.2 → 0.04 crosses 0.05 at 69.375°


@pytest.mark.parametrize(
    "body",
    [
        "aoi_deg,intensity\n0,1\n",
        "aoi_deg,intensity\n10,1\n5,0.5\n",
        "angle,value\n0,1\n10,1\n",
        "aoi_deg,intensity\n0,1\n95,0\n",
    ],
)
def test_bad_material_tables(tmp_path, body):
    path = tmp_path / "bad.csv"
    path.write_text(body)
    with pytest.raises(ConfigError):
        load_material(path)


def test_parametric_material_is_diffuse_plus_lobe():
    m = load_material("milled-aluminium-ra1.6")
    aoi = np.deg2rad(40.0)
    expected = 0.22 * np.cos(aoi) + 0.70 * np.exp(-0.5 * (40.0 / 18.0) ** 2)
    assert m.intensity(np.array([aoi]))[0] == pytest.approx(expected)
    assert m.intensity(np.deg2rad([90.0, 120.0])) == pytest.approx([0.0, 0.0])
