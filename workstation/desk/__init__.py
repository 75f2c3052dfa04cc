"""The desk's operations, one service that both front ends call: `robotconf logs`, `restart`,
`rollout` and `promote` (workstation/cli/) and the browser view's operators (workstation/ui/).
Each operation blocks, and raises CliError with one line saying why it did not happen; the
commands print that line, the browser view shows it. Nothing here parses a flag or prints."""
