"""Examples of user-supplied parts for the onboard stack (see examples/README.md)."""
