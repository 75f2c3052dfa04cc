"""The contract the robot and the server share: the error type and exit codes, diagnostics,
bounded readers of untrusted input, the Launch Request, the MQTT wire and its topic table.

The bottom layer: it imports nothing else of this project, and the robot-side agent needs
nothing above it.
"""
