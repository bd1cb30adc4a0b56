"""The ``symoro-gen`` sub-commands, one module per command (a leaf: it parses its arguments into the
workflow's options, calls the workflow of :mod:`symoro_gen.workflows` and renders the result; nothing imports
a command module but the dispatcher, :mod:`symoro_gen.cli`). :mod:`symoro_gen.commands.common` holds the
argument helpers the commands share."""
