"""The workstation shell: the `robotconf` command line, `robotconf up`'s one-machine fleet with
its embedded broker, the desk (restart, logs) and the fleet's status view.

The top layer: it may import every other; nothing imports it.
"""
