"""The `hopkinson` command line: `main.py` builds the parser; one module per sub-command.

Nothing outside this subpackage imports from it (the panel included): what a command and
the panel share lives in `analysis`, `reports` or `rig`.
"""
