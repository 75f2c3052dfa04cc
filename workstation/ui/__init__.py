"""The fleet in a browser: `robotconf ui`'s pages, live updates and operator actions."""
