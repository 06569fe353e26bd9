"""One module per ``calibproj`` subcommand (see ``calibproj.cli``)."""
