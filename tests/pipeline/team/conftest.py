"""The namespace rig's helpers are a module of the tests, not a test file."""

collect_ignore = ["netns_rig.py"]
