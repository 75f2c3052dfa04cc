"""Robot Configurator: the catalogue, configurations, validator, Launch Requests and CLI.

Importing the package stays cheap: the robot-side agent uses `configurator.types`,
`contract.launch` and `contract.wire` only.
"""

__version__ = "0.1.0"
