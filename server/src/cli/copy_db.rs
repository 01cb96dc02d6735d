//! `poseboard copy-db`: moves an installation from one database to another (SQLite to
//! PostgreSQL when it outgrows one machine, or back), keeping every id.

use clap::Args;

use crate::store::Store;

#[derive(Args, Debug)]
pub struct CopyDbArgs {
    /// The database to copy from (`sqlite://DATA_DIR/poseboard.db` or `postgres://...`); it is
    /// only read, in one snapshot.
    #[arg(long)]
    pub from: String,
    /// The database to copy into; migrated first, written in one transaction. A new SQLite file
    /// needs `?mode=rwc`.
    #[arg(long)]
    pub to: String,
    /// Replace the contents of a target that holds data (otherwise it is refused).
    #[arg(long)]
    pub force: bool,
}

pub fn run(args: CopyDbArgs) -> anyhow::Result<()> {
    super::runtime()?.block_on(async move {
        let source = Store::connect(&args.from).await?;
        let target = Store::connect(&args.to).await?;
        let report = source.copy_into(&target, args.force).await?;
        for (table, rows) in &report {
            println!("{table:>18}  {rows} rows");
        }
        println!(
            "copied into the {} database, uploaded result files included.",
            target.backend().name()
        );
        Ok(())
    })
}
