"""A brain in 30 lines: runs its scenario's goal tasks and reports each (write-a-brain.md)."""

import sys

from robotconf import brain

stop = brain.stop_signal()  # set by the agent's SIGTERM (or Ctrl-C)

request = brain.request(sys.argv[1] if len(sys.argv) > 1 else None)
speed = request.settings().get("max_linear_speed", 0.1)
print(f"{request.robot_id} runs {request.scenario} at {request.revision}", flush=True)
brain.ready()  # healthy from here on, not from process start

while not stop.is_set() and request.goals:
    for task, location in zip(request.goals, request.goal_locations, strict=True):
        goal = brain.goal(task)
        for step in range(1, 11):
            if stop.wait(0.2):  # a tenth of the way: where a real brain drives
                goal.canceled()
                break
            goal.progress(step / 10, eta=round((10 - step) * 0.2, 1), note=f"{speed} m/s")
        else:
            if location is None:
                goal.failed("NO_LOCATION", f"{task} has nowhere to go")
            else:
                goal.succeeded()
        brain.vitals({"battery": 0.9, "speed": speed})
        if stop.is_set():
            break
brain.event("info", "stopping")
