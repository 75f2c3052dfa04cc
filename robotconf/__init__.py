"""Robot Configurator's public Python namespace: `robotconf.brain` is the library a brain service
imports (docs/how-to/write-a-brain.md)."""
