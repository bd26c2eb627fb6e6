from twin.tasks import TASKS, run_task
from twin.twin import Twin


def test_pick_place_one_cycle_places_the_box():
    twin = Twin()
    run_task(twin, TASKS["pick_place"], {"cycles": 1})
    x, y = twin.object_pose("box")[:2]
    assert abs(x - -0.3) < 0.005 and abs(y - -0.55) < 0.005
