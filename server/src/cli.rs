//! The `poseboard` command line: one subcommand per way of using poseboard.

pub mod eval;

use clap::{Parser, Subcommand};

#[derive(Parser, Debug)]
#[command(
    name = "poseboard",
    version,
    about = "Evaluation and leaderboard for the BOP 6D object pose benchmark"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Evaluate a result file on a dataset and print the scores.
    Eval(Box<eval::EvalArgs>),
    /// Validate a result file without evaluating it.
    CheckResults(eval::CheckArgs),
}
