"""The operator process (the paper's "master"): joystick input, command publisher, view."""

import os

# Rerun's gRPC client logs every failed attempt to reach a viewer, and its shutdown wait, as
# ERROR/WARN lines on stderr; the operator view says it once, in its own words (``view``).
# RUST_LOG is read when Rerun is first imported, so this stays before any import of it; a
# RUST_LOG of the user's own wins.
os.environ.setdefault("RUST_LOG", "warn,re_grpc_client=off,re_sdk::recording_stream=off")
