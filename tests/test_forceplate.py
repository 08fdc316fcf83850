"""sit2stand.forceplate: COP and wrench algebra against hand-built wrenches with known answers."""

import numpy as np
import pytest

from sit2stand.forceplate import center_of_pressure, combined_cop, plate_surface, point_in_polygon, shift_moment

Z = np.array([0.0, 0.0, 1.0])


def wrench_at(cop, force, tau, about, normal=Z):
    """Moment about ``about`` of a force acting at ``cop`` plus a free moment ``tau`` about ``normal``."""
    return np.cross(np.asarray(cop) - about, force) + tau * np.asarray(normal)


def test_cop_recovers_the_point_of_application_and_free_moment():
    rng = np.random.default_rng(0)
    centre = np.array([0.2, -0.1, 0.0])
    cops = centre + np.c_[rng.uniform(-0.2, 0.2, (50, 2)), np.zeros(50)]
    forces = np.c_[rng.normal(0, 30, (50, 2)), rng.uniform(100, 900, 50)]
    taus = rng.normal(0, 3, 50)
    moments = np.array([wrench_at(c, f, t, centre) for c, f, t in zip(cops, forces, taus)])
    cop, valid, tau = center_of_pressure(forces, moments, centre, Z)
    assert valid.all()
    np.testing.assert_allclose(cop, cops, atol=1e-12)
    np.testing.assert_allclose(tau, taus, atol=1e-10)


def test_cop_on_a_tilted_plate_stays_on_its_plane():
    corners = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.01], [0.5, 0.4, 0.01], [0.0, 0.4, 0.0]])
    centre, normal = plate_surface(corners)
    assert normal[2] > 0.99
    target = centre + 0.05 * np.cross(normal, [1.0, 0.0, 0.0])
    force = np.array([20.0, 5.0, 600.0])
    cop, valid, tau = center_of_pressure(force, wrench_at(target, force, 1.5, centre, normal), centre, normal)
    assert valid
    np.testing.assert_allclose(cop, target, atol=1e-12)
    assert abs((cop - centre) @ normal) < 1e-12
    assert tau == pytest.approx(1.5)


def test_unloaded_plate_has_no_cop():
    cop, valid, tau = center_of_pressure(np.array([[0, 0, 5.0], [0, 0, np.nan]]), np.zeros((2, 3)), np.zeros(3), Z,
                                         threshold_n=20.0)
    assert not valid.any()
    assert np.isnan(cop).all() and np.isnan(tau).all()


def test_shift_moment_is_consistent_both_ways():
    f, m = np.array([3.0, -4.0, 500.0]), np.array([1.0, 2.0, 3.0])
    a, b = np.array([0.1, 0.2, 0.0]), np.array([-1.0, 0.5, 0.3])
    np.testing.assert_allclose(shift_moment(shift_moment(m, f, a, b), f, b, a), m, atol=1e-12)


def test_combined_cop_is_the_force_weighted_mean_for_vertical_forces():
    f1, f2 = np.array([0, 0, 300.0]), np.array([0, 0, 100.0])
    c1, c2 = np.array([0.5, 0.1, 0.0]), np.array([-0.3, -0.2, 0.0])
    m1, m2 = np.cross(c1, f1), np.cross(c2, f2)  # about the lab origin
    cop, valid = combined_cop([f1, f2], [m1, m2])
    assert valid
    np.testing.assert_allclose(cop, (300 * c1 + 100 * c2) / 400, atol=1e-12)


def test_point_in_polygon_either_winding_and_margin():
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    pts = np.array([[0.5, 0.5], [1.5, 0.5], [0.05, 0.5]])
    for poly in (square, square[::-1]):
        assert point_in_polygon(pts, poly).tolist() == [True, False, True]
        assert point_in_polygon(pts, poly, margin_m=0.1).tolist() == [True, False, False]


def test_degenerate_corners_raise_with_the_shape():
    with pytest.raises(ValueError, match="shape"):
        plate_surface(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="degenerate"):
        plate_surface(np.zeros((4, 3)))
