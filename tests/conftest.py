"""Shared fixtures: the seed geometry (physics.md header) and helpers to build scenarios in memory."""
import copy
import tomllib

import numpy as np
import pytest

from mechanisms.geneva_kinematics import GenevaGeometry
from scenarios.loader import builtin_text


@pytest.fixture(scope="session")
def seed_geometry():
    """Seed geometry: r = 75 mm, n = 4, R = 4 mm, l = 4 mm (physics.md header)."""
    return GenevaGeometry(crank_radius=0.075, slots=4, pin_radius=0.004, thickness=0.004)


@pytest.fixture
def lc1_raw():
    """The built-in geneva-lc1 scenario as a dict, to modify in a test."""
    return copy.deepcopy(tomllib.loads(builtin_text("geneva-lc1")))


def wrap(angle):
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi
