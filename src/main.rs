//! The `groovescope` binary: the workbench with no subcommand, otherwise the command-line tool.

fn main() {}
