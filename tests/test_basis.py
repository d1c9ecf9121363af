"""subtrace.patches.basis: the Bezier and box-spline bases against plain numpy (Bernstein
polynomials evaluated directly), and the kernels against each other (the descent mixes
``split_net`` and ``quadrant``; the point, derivative and Newton evaluators share sums)."""

from __future__ import annotations

from math import comb

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from subtrace.patches import basis


def _bern3(x):
    """Cubic Bernstein values and derivatives at x (m,): two (m,4) arrays (plain numpy)."""
    y = 1 - x
    b = np.stack([comb(3, i) * x**i * y ** (3 - i) for i in range(4)], axis=1)
    d = np.stack([-3 * y**2, 3 * y**2 - 6 * x * y, 6 * x * y - 3 * x**2, 3 * x**2], axis=1)
    return b, d


def test_quadrant_is_the_split_child():
    """``quadrant`` makes exactly the child that ``split_net`` makes."""
    rng = np.random.default_rng(3)
    nets = rng.normal(size=(1, 4, 4, 3))
    work = np.empty((8, 4, 4, 3))
    basis.split_net(nets, 0, work, 4)
    for cu in (0, 1):
        for cv in (0, 1):
            out = np.empty((2, 4, 4, 3))
            basis.quadrant(nets, 0, cu, cv, out, 0)
            assert np.array_equal(out[0], work[4 + cu + 2 * cv])


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_bicubic_evaluators_agree_with_plain_bernstein(seed):
    """bez_point, bez_eval and bez_derivatives against the tensor-product Bernstein sums in
    numpy (tolerance: a few ulps of the net's size, rounding in different orders), and the
    two derivative paths bit for bit (they share ``bez_sums``)."""
    rng = np.random.default_rng(seed)
    nets = rng.normal(size=(2, 4, 4, 3))
    uv = rng.random((8, 2))
    bu, du = _bern3(uv[:, 0])
    bv, dv = _bern3(uv[:, 1])
    P = np.einsum("mi,mj,ijk->mk", bu, bv, nets[1])
    Pu = np.einsum("mi,mj,ijk->mk", du, bv, nets[1])
    Pv = np.einsum("mi,mj,ijk->mk", bu, dv, nets[1])
    out = np.empty((6, 3))
    for m, (u, v) in enumerate(uv):
        np.testing.assert_allclose(basis.bez_point(nets, 1, u, v), P[m], atol=1e-13)
        basis.bez_eval(nets, 1, u, v, out, True)
        np.testing.assert_allclose(out[0], P[m], atol=1e-13)
        np.testing.assert_allclose(out[1], Pu[m], atol=1e-12)
        np.testing.assert_allclose(out[2], Pv[m], atol=1e-12)
        pu, pv = basis.bez_derivatives(nets[1], u, v)
        assert np.array_equal(pu, out[1]) and np.array_equal(pv, out[2])
        n = np.cross(pu, pv)
        np.testing.assert_allclose(basis.bez_normal(nets[1], u, v), n / np.linalg.norm(n),
                                   atol=1e-12)


def test_bicubic_second_derivatives_are_finite_differences():
    rng = np.random.default_rng(5)
    nets = rng.normal(size=(1, 4, 4, 3))
    out, a, b = np.empty((6, 3)), np.empty((6, 3)), np.empty((6, 3))
    s, t, h = 0.3, 0.6, 1e-6
    basis.bez_eval(nets, 0, s, t, out, True)
    basis.bez_eval(nets, 0, s + h, t, a, False)
    basis.bez_eval(nets, 0, s - h, t, b, False)
    # (a cubic's central difference of first derivatives: error O(h^2), rounding 1e-10 / h)
    np.testing.assert_allclose(out[3], (a[1] - b[1]) / (2 * h), atol=1e-8)
    np.testing.assert_allclose(out[4], (a[2] - b[2]) / (2 * h), atol=1e-8)


def test_degenerate_normal_is_taken_towards_the_centre():
    """A net collapsed along v at u = 0 (all of row 0 one point) has no normal at its
    corner: the one a little way inside, as the shading and line queries take it."""
    g = np.stack(np.meshgrid(np.arange(4.0), np.arange(4.0), indexing="ij"), -1)
    net = np.concatenate([g, np.zeros((4, 4, 1))], -1)
    net[0] = net[0, 0]
    n = basis.bez_normal(net, 0.0, 0.0)
    np.testing.assert_allclose(np.abs(n), [0.0, 0.0, 1.0], atol=1e-12)
    out = np.empty((1, 3))
    basis.bez_normals(net[None], np.zeros(1, np.int64), np.zeros((1, 2)), out)
    assert np.array_equal(out[0], n)


def test_net_bounds_contain_the_patch_and_bound_its_derivatives():
    rng = np.random.default_rng(7)
    cv = rng.normal(size=(3, 4, 4, 3))
    nets = basis.bezier_nets(cv)
    lo, hi, bound = basis.net_bounds(nets)
    # the conversion with its bounds in one pass: the same arrays, bit for bit
    for a, b in zip(basis.bezier_nets_and_bounds(cv), (nets, lo, hi, bound)):
        assert np.array_equal(a, b)
    uv = rng.random((200, 2))
    out = np.empty((6, 3))
    for m in range(3):
        for u, v in uv:
            basis.bez_eval(nets, m, u, v, out, False)
            assert (out[0] >= lo[m] - 1e-12).all() and (out[0] <= hi[m] + 1e-12).all()
            assert np.linalg.norm(out[1]) <= bound[m] * (1 + 1e-12)
            assert np.linalg.norm(out[2]) <= bound[m] * (1 + 1e-12)
    # the B-spline basis in numpy gives the same patch
    b, _ = basis.bspline_basis(uv[:, 0])
    c, _ = basis.bspline_basis(uv[:, 1])
    bu, _ = _bern3(uv[:, 0])
    bv, _ = _bern3(uv[:, 1])
    np.testing.assert_allclose(np.einsum("mi,mj,ijk->mk", b, c, cv[0]),
                               np.einsum("mi,mj,ijk->mk", bu, bv, nets[0]), atol=1e-13)


def test_triangle_nets():
    """The triangular basis: a partition of unity, the split children are the parent's
    polynomial, the monomial evaluator and the normals agree with the Bernstein form."""
    rng = np.random.default_rng(9)
    st_ = rng.dirichlet(np.ones(3), 50)[:, :2]
    B = basis.tri_bernstein(st_)
    np.testing.assert_allclose(B.sum(axis=1), 1.0, atol=1e-14)
    nets = rng.normal(size=(2, basis.N_TRI, 3))
    w = np.zeros((8, basis.N_TRI, 3))
    w[0] = nets[1]
    basis.tri_split(w, 0, 4)
    for c in range(4):
        par = basis.CHILD_ORIGIN[c] + basis.CHILD_SCALE[c] * st_
        np.testing.assert_allclose(B @ w[4 + c], basis.tri_bernstein(par) @ nets[1], atol=1e-13)
    mono = np.empty((basis.N_TRI, 3))
    basis.tri_monomials(nets, 1, basis.TRI_MONO, mono)
    out = np.empty((6, 3))
    h = 1e-7
    for s, t in st_[:10]:
        basis.tri_mono_eval(mono, s, t, out, False)
        np.testing.assert_allclose(out[0], (basis.tri_bernstein(np.array([[s, t]])) @ nets[1])[0],
                                   atol=1e-12)
        ds = (basis.tri_bernstein(np.array([[s + h, t]]))
              - basis.tri_bernstein(np.array([[s - h, t]]))) @ nets[1] / (2 * h)
        np.testing.assert_allclose(out[1], ds[0], atol=1e-6)
    n = np.empty((10, 3))
    basis.tri_normals(nets, np.ones(10, np.int64), np.ascontiguousarray(st_[:10]),
                      basis.TRI_MONO, n)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    # a flat triangle's net is its plane
    P = rng.normal(size=(3, 3))
    flat = basis.FLAT_TO_TRI @ P
    lin = (1 - st_.sum(axis=1))[:, None] * P[0] + st_[:, :1] * P[1] + st_[:, 1:] * P[2]
    np.testing.assert_allclose(B @ flat, lin, atol=1e-13)
    assert basis.tri_flatness(flat[None], 0) < 1e-14
