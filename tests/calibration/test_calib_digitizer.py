"""Digitiser transfer of film coordinates (calibration.md §6, digitiser path)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from radar_io.calibration import CalibrationError, GridTransfer, digitised_to_film, film_from_grid

AXIS = np.linspace(-30.0, 30.0, 5)
GRID = np.stack(np.meshgrid(AXIS, AXIS, indexing="ij"), axis=-1)  # (5, 5, 2), mm
# frame corners 1-4 in film coordinates: 1 → 2 is +x, 2 → 3 is +y, mean at the origin
CORNERS_FILM = np.array([[-27.0, -27.0], [27.0, -27.0], [27.0, 27.0], [-27.0, 27.0]])


def _film_to_grid(f):
    """The reference grid film lies rotated by 0.8 deg and shifted on the photo."""
    a = math.radians(0.8)
    r = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    return f @ r.T + np.array([0.31, -0.22])


def _affine_digitiser(g, mirror=False):
    """A 4× enlargement read on a digitiser (units 0.01 mm), rotated 2 deg, offset, optionally mirrored."""
    a = math.radians(2.0)
    m = 400.0 * np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    if mirror:
        m = m @ np.diag([1.0, -1.0])
    return g @ m.T + np.array([15000.0, 12000.0])


def _curved_digitiser(g):
    """The same with a radial enlarger distortion of ≈ 25 µm on the film at the frame corners."""
    r2 = np.sum(g**2, axis=-1, keepdims=True)
    return _affine_digitiser(g * (1.0 + 3.3e-7 * r2))


@pytest.mark.parametrize("mirror", [False, True])
def test_affine_enlargement_is_recovered_exactly(mirror):
    rng = np.random.default_rng(0)
    film = rng.uniform(-27.0, 27.0, size=(40, 2))
    dig = lambda f: _affine_digitiser(_film_to_grid(f), mirror)  # noqa: E731
    out = digitised_to_film(GRID, _affine_digitiser(GRID, mirror), dig(film), dig(CORNERS_FILM))
    np.testing.assert_allclose(out, film, atol=1e-9)


def test_grid_points_map_to_their_known_coordinates():
    t = GridTransfer(GRID, _curved_digitiser(GRID))
    np.testing.assert_allclose(t.to_grid(_curved_digitiser(GRID).reshape(-1, 2)), GRID.reshape(-1, 2),
                               atol=1e-9)


def test_curved_enlargement_is_recovered_to_micrometres():
    rng = np.random.default_rng(1)
    film = rng.uniform(-27.0, 27.0, size=(200, 2))
    dig = lambda f: _curved_digitiser(_film_to_grid(f))  # noqa: E731
    out = digitised_to_film(GRID, _curved_digitiser(GRID), dig(film), dig(CORNERS_FILM))
    err = np.max(np.abs(out - film))
    # bilinear interpolation error ≈ h²/8 · |f''| = 15²/8 · 6·3.3e-7·42 mm ≈ 2.3 µm for 15 mm cells
    assert err < 2.5e-3, err
    # and the distortion was real (> 10 µm on the film), several times the transfer error
    assert np.max(np.abs(_curved_digitiser(film) - _affine_digitiser(film))) / 400 > 0.01


def test_film_axes_from_corners():
    corners = np.array([[1.0, 1.0], [1.0, 3.0], [-1.0, 3.0], [-1.0, 1.0]])  # 1→2 along +y of the grid
    out = film_from_grid(np.array([[0.0, 2.0], [1.0, 2.0], [0.0, 3.0]]), corners)
    np.testing.assert_allclose(out, [[0.0, 0.0], [0.0, -1.0], [1.0, 0.0]], atol=1e-15)


def test_outside_the_grid():
    t = GridTransfer(GRID, _affine_digitiser(GRID))
    far = _affine_digitiser(np.array([[40.0, 0.0]]))
    with pytest.raises(CalibrationError, match="outside the reference grid"):
        t.to_grid(far)
    np.testing.assert_allclose(t.to_grid(far, extrapolate=True), [[40.0, 0.0]], atol=1e-9)
    with pytest.raises(CalibrationError):
        GridTransfer(GRID, GRID[:4])
