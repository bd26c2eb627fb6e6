"""docs/tutorial.md's carry.py, the user task the keep and report tests record as a golden."""

CARRY = """\
def run(twin, place_x_m: float = -0.3, place_y_m: float = -0.55, hold_s: float = 0.5):
    twin.phase("pick")
    twin.raise_()
    twin.move_to(0.2, 0.7)
    twin.suction(True)
    twin.lower()
    twin.wait(hold_s)
    if twin.frame.held_body < 0:
        raise RuntimeError("nothing picked at (0.2, 0.7)")
    twin.raise_()
    twin.phase("place")
    twin.move_to(place_x_m, place_y_m)
    twin.lower()
    twin.suction(False)
    twin.wait(hold_s)
    twin.raise_()
    x, y = twin.object_pose("box")[:2]
    error_m = ((x - place_x_m) ** 2 + (y - place_y_m) ** 2) ** 0.5
    twin.event("placed", "box", f"{error_m * 1000:.2f} mm off", error_m=error_m)
"""
