"""The motion helpers a task calls (move the pad over a point, up, down, wait for the joints to
settle), built only on the twin's commands and steps: every motion is Commands, so a replay
repeats it. Twin inherits them; they are the task API's verbs (docs/reference/task-api.md)."""

from __future__ import annotations

from itertools import chain

from twin.model.errors import OutOfReach
from twin.robot import kinematics

SHOULDER, ELBOW, Z, WRIST = range(4)
SETTLE_TOL = (5e-4, 5e-4, 2e-4, 5e-4)  # rad, rad, m, rad
SETTLE_SPEED_TOL = (5e-3, 5e-3, 2e-3, 5e-3)
SETTLE_TIMEOUT_S = 10.0


class Motions:
    """What Twin adds on top of its commands for tasks: moves that end when the joints settle."""

    def move_to(
        self, x_m: float, y_m: float, heading_rad: float | None = None, *, settle: bool = True
    ) -> None:
        """Move the pad over (x, y), keeping its heading unless one is given.

        Args:
            x_m: The point's x, metres, world frame.
            y_m: The point's y, metres, world frame.
            heading_rad: The pad's heading about z; None keeps the current one.
            settle: Step until the joints settle (False returns at once, the targets set).

        Raises:
            OutOfReach: The arm cannot reach (x, y); an `out_of_reach` event says so first.
        """
        q = self.frame.joint_q
        heading = self._heading(self.frame) if heading_rad is None else heading_rad
        try:
            sol = kinematics.choose(kinematics.ik(self.profile, x_m, y_m), (q[SHOULDER], q[ELBOW]))
            wrist = kinematics.wrist_for_heading(self.profile, sol, heading)
        except OutOfReach as err:
            self.event("out_of_reach", message=str(err), x_m=x_m, y_m=y_m)
            raise
        self.set_joint_target(SHOULDER, sol.shoulder_rad)
        self.set_joint_target(ELBOW, sol.elbow_rad)
        self.set_joint_target(WRIST, wrist)
        if settle:
            self.settle()

    def z_to(self, z_m: float, *, settle: bool = True) -> None:
        """Move the pad tip to a height with the Z joint.

        Args:
            z_m: The tip's height, metres, world frame.
            settle: Step until the joints settle.

        Raises:
            OutOfReach: The Z stroke does not reach that height (an `out_of_reach` event first).
        """
        try:
            q3 = kinematics.z_joint_for_height(self.profile, z_m)
        except OutOfReach as err:
            self.event("out_of_reach", message=str(err), z_m=z_m)
            raise
        self.set_joint_target(Z, q3)
        if settle:
            self.settle()

    def lower(self) -> None:
        """Lower the pad to the scene's "down" (on a box on the floor; mtb: the end of the Z
        stroke)."""
        self.set_joint_target(Z, self.profile.z_down())
        self.settle()

    def raise_(self) -> None:
        """Raise the pad to the scene's "up" (mtb: the top of the Z stroke)."""
        self.set_joint_target(Z, self.profile.z_up())
        self.settle()

    def settle(self, timeout_s: float = SETTLE_TIMEOUT_S) -> bool:
        """Step until every joint is at its target and still.

        Args:
            timeout_s: Simulated seconds to wait at most.

        Returns:
            True when the joints settled; False after a `settle_timeout` event.
        """
        max_steps = round(timeout_s * 1e9 / self.config.dt_ns)
        # the four joints' checks written out, on locals, with no tuple built per call: settle runs
        # most of a task's steps (1601 of pick_place's 2517); the frames come from one generator
        # (Twin._stepping), not a step() call each
        t0, t1, t2, t3 = self._targets
        e0, e1, e2, e3 = SETTLE_TOL
        v0, v1, v2, v3 = SETTLE_SPEED_TOL
        if max_steps > 0:  # max_steps checks, each before a step: the last step's frame unchecked
            for f in chain((self.frame,), self._stepping(max_steps - 1)):
                q, qd = f.joint_q, f.joint_qd
                if not (
                    abs(q[0] - t0) > e0
                    or abs(qd[0]) > v0
                    or abs(q[1] - t1) > e1
                    or abs(qd[1]) > v1
                    or abs(q[2] - t2) > e2
                    or abs(qd[2]) > v2
                    or abs(q[3] - t3) > e3
                    or abs(qd[3]) > v3
                ):
                    return True
            self.step()
        self.event("settle_timeout", message=f"joints did not reach their targets in {timeout_s} s")
        return False
