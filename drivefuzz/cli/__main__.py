"""``python -m drivefuzz.cli``: the same as the ``drivefuzz`` command."""

from drivefuzz.cli import main

main(prog_name="drivefuzz")
