"""Tests that kill the mutants of analysis/response.py the other tests let survive (docs/mutation-testing.md)."""
