"""The read model: how the fleet is read, shared by the reconciler and the workstation.

The retained-topic mirror (`retained.py`), the robots it shows (`observed.py`, `robot_goals.py`),
the fleet status's verdicts (`verdicts.py`), the goal-outcome ledger and what it answers
(`ledger.py`, `outcomes.py`, `timeline.py`, `events.py`), the commits behind a revision
(`commits.py`) and the bounded HTTP edge the listeners and the browser view run on
(`http_edge.py`). It stands on `contract` and `configurator` alone: the reconciler's loop and
the desk both read the fleet through it, and neither is needed to read it.
"""
