//! `poseboard backup` and `poseboard restore`: an operator's copy of a live installation in
//! one file, and the way back (see [`crate::store::backup`] for how each database is read).
//!
//! A backup is written under a temporary name beside its destination, checked, and only then
//! renamed into place, so an interrupted or failed backup never leaves a file that looks like a
//! good one. A restore reads a private copy of the backup, migrated to this version, so that
//! a backup taken by an older poseboard restores and the backup file itself is never changed.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::Args;

use crate::config::Config;
use crate::store::Store;
use crate::store::copy::CopyReport;

#[derive(Args, Debug)]
pub struct BackupArgs {
    #[command(flatten)]
    pub config: Config,
    /// The backup file to write (a SQLite database); it must not exist unless --force.
    pub file: PathBuf,
    /// Replace an existing file.
    #[arg(long)]
    pub force: bool,
}

#[derive(Args, Debug)]
pub struct RestoreArgs {
    #[command(flatten)]
    pub config: Config,
    /// A file `poseboard backup` wrote.
    pub file: PathBuf,
    /// Replace the contents of a database that holds data (otherwise it is refused).
    #[arg(long)]
    pub force: bool,
}

pub fn backup(args: BackupArgs) -> anyhow::Result<()> {
    if args.file.exists() && !args.force {
        bail!(
            "{} exists: choose a new file, or pass --force to replace it",
            args.file.display()
        );
    }
    let folder = match args.file.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    // A name in the destination's folder, so that the final rename is atomic; the temporary
    // file itself is removed first, because `VACUUM INTO` only writes a file that is not there.
    let partial = tempfile::Builder::new()
        .prefix(".poseboard-backup-")
        .suffix(".partial")
        .tempfile_in(&folder)
        .with_context(|| format!("cannot write in {}", folder.display()))?
        .into_temp_path();
    std::fs::remove_file(&partial)?;
    let result = super::runtime()?.block_on(async {
        let store = Store::connect(&args.config.database_url()).await?;
        store.backup_to(&partial).await?;
        let copy = Store::connect(&sqlite_file(&partial)?).await?;
        let problems = copy.integrity_problems().await?;
        if !problems.is_empty() {
            bail!(
                "the copy failed SQLite's integrity check: {}",
                problems.join("; ")
            );
        }
        let counts = copy.row_counts().await?;
        copy.close_as_one_file().await;
        Ok(counts)
    });
    let counts = match result {
        Ok(counts) => counts,
        Err(e) => {
            remove_sqlite_files(&partial);
            return Err(e);
        }
    };
    std::fs::rename(&partial, &args.file)
        .with_context(|| format!("cannot move the backup to {}", args.file.display()))?;
    print_counts(&counts);
    println!(
        "backed up into {} (restore with `poseboard restore {}`)",
        args.file.display(),
        args.file.display()
    );
    Ok(())
}

pub fn restore(args: RestoreArgs) -> anyhow::Result<()> {
    if !args.file.is_file() {
        bail!("{} is not a file", args.file.display());
    }
    std::fs::create_dir_all(&args.config.data_dir)?;
    let work = tempfile::Builder::new()
        .prefix(".poseboard-restore-")
        .suffix(".db")
        .tempfile_in(&args.config.data_dir)?
        .into_temp_path();
    std::fs::copy(&args.file, &work)
        .with_context(|| format!("cannot read {}", args.file.display()))?;
    let result = super::runtime()?.block_on(async {
        let not_a_backup = || {
            format!(
                "{} is not a poseboard backup (a SQLite database `poseboard backup` wrote)",
                args.file.display()
            )
        };
        let source = Store::connect(&sqlite_file(&work)?)
            .await
            .with_context(not_a_backup)?;
        let problems = source
            .integrity_problems()
            .await
            .with_context(not_a_backup)?;
        if !problems.is_empty() {
            bail!(
                "{} is damaged (SQLite's integrity check: {})",
                args.file.display(),
                problems.join("; ")
            );
        }
        let state = source.migration_state().await.with_context(not_a_backup)?;
        if !state.unknown.is_empty() {
            bail!(
                "{} was written by a newer poseboard (migrations {:?} are unknown here): restore \
                 it with that version",
                args.file.display(),
                state.unknown
            );
        }
        source.migrate().await?;
        let target = Store::connect(&args.config.database_url()).await?;
        let report = source.copy_into(&target, args.force).await?;
        let kind = target.backend().name();
        source.close_as_one_file().await;
        Ok((report, kind))
    });
    remove_sqlite_files(&work);
    let (report, kind) = result?;
    print_counts(&report);
    println!("restored {} into the {kind} database", args.file.display());
    Ok(())
}

fn sqlite_file(path: &Path) -> anyhow::Result<String> {
    let name = path
        .to_str()
        .with_context(|| format!("{} is not a UTF-8 path", path.display()))?;
    Ok(format!("sqlite://{name}?mode=rwc"))
}

/// Removes a SQLite file and the journal files SQLite may have left beside it.
fn remove_sqlite_files(path: &Path) {
    for suffix in ["", "-wal", "-shm", "-journal"] {
        let mut name = path.as_os_str().to_owned();
        name.push(suffix);
        let _ = std::fs::remove_file(PathBuf::from(name));
    }
}

fn print_counts(counts: &CopyReport) {
    for (table, rows) in counts {
        println!("{table:>18}  {rows} rows");
    }
}
