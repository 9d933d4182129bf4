"""Shared test fixtures."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh


@pytest.fixture
def flat_plate():
    """A 60 x 60 x 2 mm white plate centred on O (a minimal part for the surrogate) and a sensor pose
    looking straight down at its top face from 1 mm beyond R."""
    plate = trimesh.creation.box((0.06, 0.06, 0.002))

    class Plate:
        mesh, sensor, material = plate, "keyence-lj-x8080", "white-diffuse"
        rotation_centre = np.zeros(3)

        class motion:
            length, step, n_profiles = 0.04, 0.5e-3, 80

    down = np.array([[0, 1, 0, 0], [1, 0, 0, 0], [0, 0, -1, 0.001], [0, 0, 0, 1.0]])
    return Plate(), down
