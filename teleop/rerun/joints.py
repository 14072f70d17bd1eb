"""The joint instrument's part of the live view (:class:`teleop.rerun.logger.RerunLogger` inherits it):
per joint the torque and angle series and the tendon pair in 3D coloured by tension (entity layout in
:mod:`teleop.rerun.logger`)."""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from teleop.rerun.layout import JOINT_SPACING, JointView, route_points, route_segments, tension_colors

__all__ = ["JointLogging", "arc_length", "ORANGE", "BLUE"]

ORANGE, BLUE = (255, 127, 14, 255), (31, 119, 180, 255)


def arc_length(pts: np.ndarray) -> np.ndarray:
    """Arc length [m] at each vertex of the polyline ``pts`` (shape (n, 3) [m]), shape (n,)."""
    return np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))]


class JointLogging:
    """Joint logging of :class:`~teleop.rerun.logger.RerunLogger` (which provides ``_rec``, ``_rr``,
    ``_paths``, ``_start`` and ``_set_time``)."""

    _rec: Any
    _rr: Any
    _paths: dict[str, str]

    def _start(self, t: float) -> None:  # pragma: no cover - RerunLogger's
        raise NotImplementedError

    def _set_time(self, rec: Any, t: float) -> None:  # pragma: no cover - RerunLogger's
        raise NotImplementedError

    def _init_joints(self, joints: Sequence[JointView]) -> None:
        """Each joint's tendon routes placed in 3D: joint k at z = -k JOINT_SPACING, tendon b above a."""
        self._joints = {j.name: (k, j) for k, j in enumerate(joints)}
        self._joint_routes: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for name, (k, j) in self._joints.items():
            for side, runs in (("a", j.route_a), ("b", j.route_b)):
                dz = -k * JOINT_SPACING + (0.1 * JOINT_SPACING if side == "b" else 0.0)
                pts = route_points(runs) + np.array([0.0, 0.0, dz])
                self._joint_routes[f"{name}/{side}"] = (pts, arc_length(pts))

    def _log_joint_statics(self) -> None:
        """The tendon routes, static and grey (at the first log and at the start of every .rrd segment)."""
        for key, (pts, _arc) in self._joint_routes.items():
            self._rec.log(f"instrument/{key}/route",
                          self._rr.LineStrips3D([pts], radii=0.001, colors=[(120, 120, 120, 255)]), static=True)

    def _log_joint_routes(self, t: float) -> None:
        """At the first log: every tendon at rest (0 N) at ``t`` [s], so that the 3D view has its tendons from
        where the recording starts (the grey routes: :meth:`_log_joint_statics`)."""
        self._set_time(self._rec, t)
        for key, (pts, arc) in self._joint_routes.items():
            segs = route_segments(pts, arc, np.linspace(0.0, 1.0, 21))
            self._rec.log(f"instrument/{key}/tension",
                          self._rr.LineStrips3D(segs, radii=0.003, colors=tension_colors(np.zeros(20))))

    def log_joint(self, t: float, joint: str, *, torque_hat: float | None = None, torque_true: float | None = None,
                  angle_hat: float | None = None, angle_true: float | None = None,
                  profiles: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """One joint of a joint instrument at ``t`` [s]: torque [N m] and angle [rad] series (None: skipped)
        and, with ``profiles`` (node tensions [N] of tendons a and b, proximal to distal, each shape (n,)),
        the tendons in 3D coloured by tension and the tip labelled with the torque and angle given.

        Raises
        ------
        KeyError
            ``joint`` is not one of the logger's ``joints``.
        """
        rec = self._rec
        if rec is None:
            return
        self._joints[joint]          # noqa: B018 - an unknown joint is an error, not a new entity
        rr = self._rr
        self._start(t)
        self._set_time(rec, t)
        for q, v in (("torque/hat", torque_hat), ("torque/true", torque_true), ("angle/hat", angle_hat),
                     ("angle/true", angle_true)):
            if v is None:
                continue
            entity = f"joints/{joint}/{q}"
            if entity not in self._paths:
                self._paths[entity] = entity
                color = ORANGE if q.endswith("hat") else BLUE
                rec.log(entity, rr.SeriesLines(names=f"{q.split('/')[0]} {'est' if q.endswith('hat') else 'true'}",
                                               colors=color, widths=1.5), static=True)
            rec.log(entity, rr.Scalars.from_fields(scalars=[float(v)]))
        if profiles is None:
            return
        for side, T in zip("ab", profiles, strict=False):
            pts, arc = self._joint_routes[f"{joint}/{side}"]
            T = np.asarray(T, dtype=np.float64)
            segs = route_segments(pts, arc, np.linspace(0.0, 1.0, T.size))
            rec.log(f"instrument/{joint}/{side}/tension",
                    rr.LineStrips3D(segs, radii=0.003, colors=tension_colors(0.5 * (T[:-1] + T[1:]))))
        tip = self._joint_routes[f"{joint}/a"][0][-1]
        label = joint + "".join(f", {q} {v:.3f}" + ("" if w is None else f" (true {w:.3f})") + f" {u}"
                                for q, v, w, u in (("torque", torque_hat, torque_true, "N m"),
                                                   ("angle", angle_hat, angle_true, "rad")) if v is not None)
        rec.log(f"instrument/{joint}/tip", rr.Points3D([tip], radii=0.006, labels=[label], show_labels=True))
