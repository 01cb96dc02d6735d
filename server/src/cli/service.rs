//! `poseboard serve`, `worker`, `migrate` and `dataset`: the service side of the command line.

use std::path::PathBuf;

use clap::{Args, Subcommand};

use crate::app::{App, Role};
use crate::config::{Config, ServeConfig};
use crate::demo::{
    CHALLENGE_LAYOUTS, CORE_LAYOUTS, SynthOptions, write_challenge_miniature, write_core_miniature,
    write_dataset, write_demo_coco_results, write_demo_results,
};
use crate::domain::{Password, TokenLabel, UserName};
use crate::service::accounts;
use crate::shutdown::Shutdown;
use crate::web::routes::deadlines::Deadlines;
use crate::web::routes::snapshots::DeadlineBoards;

#[derive(Args, Debug)]
pub struct ServeArgs {
    #[command(flatten)]
    pub config: ServeConfig,
}

#[derive(Args, Debug)]
pub struct WorkerArgs {
    #[command(flatten)]
    pub config: Config,
    /// Serve `/metrics`, `/healthz` and `/readyz` on this address (a worker has no pages).
    #[arg(long, env = "POSEBOARD_METRICS_BIND")]
    pub metrics_bind: Option<std::net::SocketAddr>,
}

#[derive(Args, Debug)]
pub struct MigrateArgs {
    #[command(flatten)]
    pub config: Config,
}

#[derive(Subcommand, Debug)]
pub enum DatasetCommand {
    /// Write the synthetic demo dataset (BOP format) into DIR.
    Synth {
        dir: PathBuf,
        #[arg(long, default_value_t = SynthOptions::default().seed)]
        seed: u64,
        #[arg(long, default_value_t = SynthOptions::default().scenes)]
        scenes: u32,
        #[arg(long, default_value_t = SynthOptions::default().images_per_scene)]
        images_per_scene: u32,
        /// Lay it out as this BOP dataset is published instead of plainly: a core dataset
        /// (lmo, tless, tudl, icbin, itodd, hb, ycbv: split folder, camera file, depth scale,
        /// gray images, image size and file formats) or one the challenge added in 2024
        /// (hopev2, handal, ipd, xyzibd, itoddmv, hot3d: per-sensor files, fisheye cameras,
        /// JPEG images).
        #[arg(long, conflicts_with = "size")]
        layout: Option<String>,
        /// Image size WIDTHxHEIGHT of a plain dataset (the intrinsics scale with it), e.g. to
        /// compare with a miniature of the same size.
        #[arg(long, value_parser = parse_size)]
        size: Option<(u32, u32)>,
        /// Object ids 1 to N (at least 6): beyond the six shapes, copies of them under further
        /// ids, e.g. 30 for a board as wide as T-LESS's.
        #[arg(long, default_value_t = SynthOptions::default().objects)]
        objects: u32,
    },
    /// Compute once what scoring needs of DIR whatever the result file (decoded depth,
    /// ground-truth renders), for `poseboard eval` and the Python package to read; checks and
    /// repairs an existing prepared form.
    Prepare(super::prepare::PrepareArgs),
    /// Write the demo result files (precise, noisy, rough) for a synthetic dataset into OUT.
    DemoResults {
        dataset: PathBuf,
        out: PathBuf,
        #[arg(long, default_value_t = 11)]
        seed: u64,
        /// Write the BOP'22 2D files instead (demo-detector boxes, demo-segmenter masks).
        #[arg(long)]
        coco: bool,
    },
}

/// `WIDTHxHEIGHT`, both positive.
fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let parsed = s
        .split_once('x')
        .and_then(|(w, h)| Some((w.parse::<u32>().ok()?, h.parse::<u32>().ok()?)));
    match parsed {
        Some((w, h)) if w > 0 && h > 0 && w <= 8192 && h <= 8192 => Ok((w, h)),
        _ => Err(format!(
            "`{s}` is no image size: expected WIDTHxHEIGHT, e.g. 720x540 (at most 8192x8192)"
        )),
    }
}

pub fn serve(args: ServeArgs) -> anyhow::Result<()> {
    crate::ops::logging::init(args.config.common.log_format);
    let rt = super::runtime()?;
    let result = rt.block_on(async move {
        let shutdown = Shutdown::on_signals()?;
        // The port first: a server that cannot have it stops before it touches anything (a
        // worker started earlier would claim a job and leave it to wait out its lease).
        let listener = tokio::net::TcpListener::bind(args.config.bind).await?;
        let config = args.config.common.beside_the_web();
        let demo = !config.no_demo && config.datasets.is_none();
        if demo {
            crate::demo::setup::ensure_demo_dataset(&config.datasets_dir()).await?;
        }
        let app = App::start(config, Role::Server).await?;
        if demo {
            crate::demo::setup::ensure_demo_submissions(&app).await?;
        }
        crate::service::rescoring::flag_stale(&app.store).await?;
        let workers = crate::worker::spawn_workers(&app, &shutdown);
        // The permalinks of the snapshots taken at deadlines: no request says the host then.
        let site = match &app.config.public_url {
            Some(url) => url.trim_end_matches('/').to_string(),
            None => format!("http://{}", listener.local_addr()?),
        };
        let deadlines = crate::worker::spawn_deadline_watch(
            &app,
            DeadlineBoards::new(app.clone(), site),
            &shutdown,
            std::time::Duration::from_secs(args.config.challenge_check_secs),
        );
        // Scripts and tests read this line to learn the port when binding to port 0.
        println!("poseboard listening on http://{}", listener.local_addr()?);
        tracing::info!(address = %listener.local_addr()?, "listening");
        let http = args.config.http;
        let router = crate::web::routes::router(app, Deadlines::of(&http));
        let stop = shutdown.clone();
        crate::web::serve::serve(listener, router, &http, async move { stop.wait().await }).await;
        join_all(workers).await;
        let _ = deadlines.await;
        Ok(())
    });
    // An evaluation cancelled on a signal stops at its next image; nothing waits for it.
    rt.shutdown_timeout(std::time::Duration::from_secs(1));
    result
}

pub fn worker(args: WorkerArgs) -> anyhow::Result<()> {
    crate::ops::logging::init(args.config.log_format);
    if args.config.workers == 0 {
        anyhow::bail!("--workers must be at least 1 for `poseboard worker`");
    }
    let rt = super::runtime()?;
    let result = rt.block_on(async move {
        let shutdown = Shutdown::on_signals()?;
        // A worker only evaluates: it registers no dataset and needs no upload folder.
        let app = App::start(args.config, Role::Worker).await?;
        if let Some(addr) = args.metrics_bind {
            let listener = tokio::net::TcpListener::bind(addr).await?;
            println!(
                "poseboard worker metrics on http://{}",
                listener.local_addr()?
            );
            tokio::spawn(crate::web::routes::ops::serve_alone(app.clone(), listener));
        }
        crate::service::rescoring::flag_stale(&app.store).await?;
        join_all(crate::worker::spawn_workers(&app, &shutdown)).await;
        Ok(())
    });
    rt.shutdown_timeout(std::time::Duration::from_secs(1));
    result
}

async fn join_all(handles: Vec<tokio::task::JoinHandle<()>>) {
    for h in handles {
        let _ = h.await;
    }
}

pub fn migrate(args: MigrateArgs) -> anyhow::Result<()> {
    crate::ops::logging::init(args.config.log_format);
    super::runtime()?.block_on(async move {
        let store = crate::store::Store::connect(&args.config.database_url()).await?;
        store.migrate().await?;
        println!("migrations applied");
        Ok(())
    })
}

pub fn dataset(cmd: DatasetCommand) -> anyhow::Result<()> {
    match cmd {
        DatasetCommand::Synth {
            dir,
            seed,
            scenes,
            images_per_scene,
            layout,
            size,
            objects,
        } => {
            let opts = SynthOptions {
                seed,
                scenes,
                images_per_scene,
                image_size: size.unwrap_or(SynthOptions::default().image_size),
                objects,
            };
            match layout {
                None => write_dataset(&dir, &opts)?,
                Some(name) => {
                    let (w, h) = if let Some(layout) = CORE_LAYOUTS.iter().find(|l| l.name == name)
                    {
                        write_core_miniature(&dir, layout, &opts)?;
                        layout.published_size
                    } else if let Some(layout) = CHALLENGE_LAYOUTS.iter().find(|l| l.name == name) {
                        write_challenge_miniature(&dir, layout, &opts)?;
                        layout.published_size
                    } else {
                        let names: Vec<&str> = CORE_LAYOUTS
                            .iter()
                            .map(|l| l.name)
                            .chain(CHALLENGE_LAYOUTS.iter().map(|l| l.name))
                            .collect();
                        anyhow::bail!("no layout `{name}`: expected one of {}", names.join(", "));
                    };
                    println!("laid out as {name} is published, {w} x {h}");
                }
            }
            println!("wrote a synthetic BOP dataset to {}", dir.display());
            Ok(())
        }
        DatasetCommand::Prepare(args) => super::prepare::run(args),
        DatasetCommand::DemoResults {
            dataset,
            out,
            seed,
            coco,
        } => {
            std::fs::create_dir_all(&out)?;
            let demos = if coco {
                write_demo_coco_results(&dataset, &out, seed)?
            } else {
                write_demo_results(&dataset, &out, seed)?
            };
            for demo in demos {
                println!("{}: {}", demo.method, demo.path.display());
            }
            Ok(())
        }
    }
}

#[derive(Args, Debug)]
pub struct AdminArgs {
    #[command(subcommand)]
    pub command: AdminCommand,
    #[command(flatten)]
    pub config: Config,
}

#[derive(Subcommand, Debug)]
pub enum AdminCommand {
    /// Create an account; the password is read from a file so it never appears in a process list.
    CreateUser {
        name: String,
        #[arg(long)]
        password_file: PathBuf,
        /// Make the account an administrator.
        #[arg(long)]
        admin: bool,
    },
    /// Print a new API token for the user (shown once; only its hash is stored).
    CreateToken {
        name: String,
        /// A label for the token.
        #[arg(long, default_value = "command line")]
        label: String,
    },
}

pub fn admin(args: AdminArgs) -> anyhow::Result<()> {
    super::runtime()?.block_on(async move {
        std::fs::create_dir_all(&args.config.data_dir)?;
        let store = crate::store::Store::connect(&args.config.database_url()).await?;
        store.migrate().await?;
        match args.command {
            AdminCommand::CreateUser {
                name,
                password_file,
                admin,
            } => {
                let password = std::fs::read_to_string(&password_file)?;
                let password = Password::parse(password.trim_end_matches(['\n', '\r']))?;
                let name = UserName::parse(&name)?;
                accounts::register(&store, &name, &password, admin).await?;
                println!(
                    "created {}{name}",
                    if admin { "administrator " } else { "user " }
                );
            }
            AdminCommand::CreateToken { name, label } => {
                let name = UserName::parse(&name)?;
                let user = store
                    .user_by_name(name.as_str())
                    .await?
                    .ok_or_else(|| anyhow::anyhow!("no user `{name}`"))?;
                let token =
                    accounts::create_token(&store, user.id, &TokenLabel::parse(&label)?).await?;
                println!("{token}");
            }
        }
        Ok(())
    })
}
