"""Sub-commands of the ``groundstation`` command line, one module each."""
