"""One module per ``trainer`` sub-command: ``add_parser(subparsers)`` registers it, ``run(args)`` runs it."""
