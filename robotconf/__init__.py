"""Robot Configurator's one import namespace. Installed, everything lives under `robotconf.`
and nothing else lands at the top of site-packages: the repository's folders are its
subpackages (robotconf/agent -> ../agent, and so on for contract, configurator, readmodel,
reconciler and workstation). `robotconf.brain` is the library a brain service imports
(docs/how-to/write-a-brain.md)."""
