"""One module per `clutch-sim` subcommand: add_parser(subparsers) and run(args)."""
