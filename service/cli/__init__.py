"""The `shockbench` command line: one module per group of subcommands, registered in main.py."""
