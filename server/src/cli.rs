//! The `poseboard` command line: one subcommand per way of using poseboard.

pub mod backup;
pub mod copy_db;
pub mod eval;
pub mod prepare;
pub mod service;
pub mod submit;

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
    /// Run the web service (leaderboards, uploads) with its evaluation workers.
    Serve(service::ServeArgs),
    /// Run evaluation workers only, sharing a PostgreSQL database with a `serve`.
    Worker(service::WorkerArgs),
    /// Apply the database migrations and exit.
    Migrate(service::MigrateArgs),
    /// Copy every row of one database into another (SQLite to PostgreSQL or back).
    CopyDb(copy_db::CopyDbArgs),
    /// Write a consistent copy of the database, while the service runs, into one SQLite file.
    Backup(backup::BackupArgs),
    /// Bring back a database from a file `poseboard backup` wrote (into SQLite or PostgreSQL).
    Restore(backup::RestoreArgs),
    /// Dataset tools.
    #[command(subcommand)]
    Dataset(service::DatasetCommand),
    /// Accounts: create users and API tokens (for scripts and first administrators).
    Admin(service::AdminArgs),
    /// Evaluate a result file on a dataset and print the scores.
    Eval(Box<eval::EvalArgs>),
    /// Validate a result file without evaluating it.
    CheckResults(eval::CheckArgs),
    /// Submit a result file to a poseboard server, follow its evaluation and print the scores.
    Submit(Box<submit::SubmitArgs>),
}

/// Runs a parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Eval(args) => eval::run_eval(*args),
        Command::CheckResults(args) => eval::run_check(args),
        Command::Submit(args) => submit::run(*args),
        Command::Serve(args) => service::serve(args),
        Command::Worker(args) => service::worker(args),
        Command::Migrate(args) => service::migrate(args),
        Command::CopyDb(args) => copy_db::run(args),
        Command::Backup(args) => backup::backup(args),
        Command::Restore(args) => backup::restore(args),
        Command::Dataset(cmd) => service::dataset(cmd),
        Command::Admin(args) => service::admin(args),
    }
}

/// The runtime of a command that talks to the database or a server.
fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    Ok(tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?)
}
