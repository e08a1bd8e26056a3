"""The ``truestep`` commands, one module each: its parser (``add_parser``) and what it
runs (``main``), a call into :mod:`truestep.api` or the part of the package the command
exists for. :mod:`truestep.cli` puts them together. Each module imports what its command
uses when the command runs, so ``truestep --help`` loads no engine, pandas or scipy."""
