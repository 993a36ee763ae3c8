"""The toy resolution rule registers itself when imported: only its test imports it (never
the doctest collection)."""

collect_ignore = ["toy_rule.py"]
