"""Registration back-ends behind one interface, picked by name (``RegistrationConfig.backend``).

========  ===========================================  ======================================
name      module                                       methods
========  ===========================================  ======================================
fast      :mod:`optipose.registration.fast`            point_to_point, point_to_plane
plain     :mod:`optipose.registration.fast` (numpy)    point_to_point, point_to_plane
open3d    :mod:`optipose.registration.open3d_icp`      point_to_point, point_to_plane, generalized
========  ===========================================  ======================================

A method the named back-end does not run goes to Open3D (generalized ICP has no fast path). The
built-in back-ends are listed as ``"module:Class"`` and imported on first use, so importing this module
(and validating an objective's names against :data:`BACKENDS`) loads neither SciPy, numba nor Open3D.
Every back-end passes the contract tests in ``tests/test_registration_backends.py``; add one with
:func:`register_backend`.
"""

from __future__ import annotations

import importlib
from dataclasses import replace
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

from optipose.errors import ConfigError
from optipose.registration.result import MIN_POINTS, Matches, Registration

if TYPE_CHECKING:
    from optipose.registration.config import RegistrationConfig

__all__ = ["RegistrationBackend", "BACKENDS", "get_backend", "register_backend", "backend_for", "register"]


@runtime_checkable
class RegistrationBackend(Protocol):
    """What a registration back-end provides.

    methods : the ``RegistrationConfig.method`` values it runs.
    takes_initial : it uses ``initial`` (the source's :class:`Matches` at identity) when given, so a
        caller registering many subsets of the same clouds may search them once.
    register : ICP of ``source`` (n, 3) m onto ``reference`` from identity, under ``cfg``. ``reference``
        is a :class:`optipose.registration.reference.SurfaceReference` or
        :class:`optipose.registration.sampled.SampledReference`
        (``closest``, ``follow``, ``nearest``, ``sample``). It returns a failed :class:`Registration`
        (``ok`` False, ``failure`` saying why), never raises, for a problem in the data.
    """

    methods: tuple[str, ...]
    takes_initial: bool

    def register(
        self, source: np.ndarray, reference, cfg: RegistrationConfig, initial: Matches | None = None
    ) -> Registration: ...


BACKENDS: dict[str, RegistrationBackend | str] = {
    "fast": "optipose.registration.fast:FastBackend",
    "plain": "optipose.registration.fast:PlainBackend",
    "open3d": "optipose.registration.open3d_icp:Open3DBackend",
}


def register_backend(name: str, backend: RegistrationBackend) -> None:
    """Make ``backend`` available as ``RegistrationConfig.backend = name`` (replacing any of that name)."""
    if not isinstance(backend, RegistrationBackend):
        raise TypeError(f"registration backend '{name}' needs methods, takes_initial and register(); got {backend!r}")
    BACKENDS[str(name)] = backend


def get_backend(name: str) -> RegistrationBackend:
    """The back-end registered as ``name``; :class:`ConfigError` if there is none."""
    entry = BACKENDS.get(name)
    if entry is None:
        raise ConfigError(f"unknown registration backend '{name}' (registered: {', '.join(BACKENDS)})")
    if isinstance(entry, str):  # a built-in, imported on first use
        module, cls = entry.split(":")
        entry = BACKENDS[name] = getattr(importlib.import_module(module), cls)()
    return entry


def backend_for(cfg: RegistrationConfig) -> RegistrationBackend:
    """The back-end that runs ``cfg``: the named one, or Open3D for a method the named one lacks."""
    backend = get_backend(cfg.backend)
    return backend if cfg.method in backend.methods else get_backend("open3d")


def register(
    source: np.ndarray,
    reference,
    cfg: RegistrationConfig,
    initial: Matches | None = None,
    start: tuple[np.ndarray, np.ndarray] | None = None,
) -> Registration:
    """Register a scan ``source`` (n, 3) m onto ``reference`` from identity (ICP, see :func:`backend_for`).

    initial : the reference matches of ``source`` at identity, if already known (they are the same for
        every subset that contains a sensor, so the evaluator searches them once per sensor).
    start : (T (4, 4), ids (n,)) for back-ends that take ``initial``: start from pose T instead of identity,
        with each point's match there as a hint (the evaluator starts a subset of several sensors where
        its own sensors' registrations, combined, put it; see :func:`combined_start`).
    Returns a :class:`Registration`; fewer than :data:`MIN_POINTS` points fail without a back-end call, and
    one that ends with an RMSE over ``cfg.max_rmse`` (when set) fails with that reason.
    """
    backend = backend_for(cfg)
    if len(source) < MIN_POINTS:
        return Registration.failed(len(source), f"only {len(source)} points")
    if start is not None:
        reg = backend.register(source, reference, cfg, initial, start=start)
    else:
        reg = backend.register(source, reference, cfg, initial)
    if cfg.max_rmse > 0 and reg.ok and reg.rmse > cfg.max_rmse:
        # converged, but in a wrong basin or onto a wrong reference: the ICP cannot tell, the residual can
        reg = replace(reg, failure=f"rmse {reg.rmse * 1e3:.3f} mm over max_rmse_mm = {cfg.max_rmse * 1e3:g}")
    return reg


def combined_start(parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> np.ndarray:
    """Where the registrations of several clouds put them together, to second order: (4, 4).

    parts : per cloud (T (4, 4) its own registration, H (6, 6) its information about c, c (3,) its
    centroid there). Each registration's quadratic model (H about its pose) is moved to a common origin
    and the models are added, as the clouds' normal equations add; the minimum of the sum is the pose.
    ICP from there has next to nothing left to do (its fixed point is the same); a direction no cloud
    sees stays where the first registration left it, which is identity's there (a registration from
    identity never moves along a direction its cloud cannot see).
    """
    from scipy.spatial.transform import Rotation

    T_ref = parts[0][0]
    o = np.mean([c for _, _, c in parts], axis=0)
    H_sum, g = np.zeros((6, 6)), np.zeros(6)
    for T, H, c in parts:
        D = T @ np.linalg.inv(T_ref)
        x = np.concatenate([Rotation.from_matrix(D[:3, :3]).as_rotvec(), D[:3, :3] @ o + D[:3, 3] - o])
        M = np.eye(6)
        M[3:, :3] = -np.cross(np.eye(3), c - o)  # rows about c -> about o: (c - o) x n added to the rotation part
        H_o = M.T @ H @ M
        H_sum += H_o
        g += H_o @ x
    x, *_ = np.linalg.lstsq(H_sum, g, rcond=1e-12)
    R = Rotation.from_rotvec(x[:3]).as_matrix()
    D = np.eye(4)
    D[:3, :3], D[:3, 3] = R, o + x[3:] - R @ o
    return D @ T_ref
