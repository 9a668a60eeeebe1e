"""One case of :func:`vesselhex.mesh_many`, in a process of its own (``python -m vesselhex._case``):
its job read on standard input, its summary row written on standard output, as the command line's
``vesselhex batch-case`` does. A crash here ends this process only."""

import sys

from . import _native

if __name__ == "__main__":
    sys.exit(_native.batch_child())
