"""`robotconf ui`: the fleet in a browser, served by the reconciler's bounded HTTP edge."""

DEFAULT_LISTEN = "127.0.0.1:8765"  # where the UI listens unless told
