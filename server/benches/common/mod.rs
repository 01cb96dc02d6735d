//! What the benchmarks share: their settings from the environment, a private PostgreSQL
//! database, and the real `poseboard serve` they drive. (A folder with `mod.rs`, so that cargo
//! does not take it for a benchmark of its own.)

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};

pub type Res<T> = Result<T, Box<dyn std::error::Error + Send + Sync>>;

/// The number in the environment variable `name`, or `default` when unset or unreadable.
pub fn env_num(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// A fresh PostgreSQL database for one run, dropped afterwards.
pub struct PgDb {
    admin: String,
    pub name: String,
    pub url: String,
}

impl PgDb {
    /// A database named after `label` and this process, made through `admin` (a URL of a
    /// database the benchmark may create others from).
    pub fn create(admin: &str, label: &str) -> Res<PgDb> {
        let name = format!("poseboard_bench_{label}_{}", std::process::id());
        pg_exec(admin, &format!("DROP DATABASE IF EXISTS {name}"))?;
        pg_exec(admin, &format!("CREATE DATABASE {name}"))?;
        let base = admin.rsplit_once('/').map_or(admin, |(b, _)| b);
        Ok(PgDb {
            admin: admin.to_string(),
            url: format!("{base}/{name}"),
            name,
        })
    }
}

impl Drop for PgDb {
    fn drop(&mut self) {
        let _ = pg_exec(
            &self.admin,
            &format!("DROP DATABASE IF EXISTS {} WITH (FORCE)", self.name),
        );
    }
}

/// Runs one statement on its own runtime: call it outside any async context.
fn pg_exec(url: &str, sql: &str) -> Res<()> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?
        .block_on(async {
            use sqlx::Connection;
            let mut conn = sqlx::PgConnection::connect(url).await?;
            sqlx::query(sqlx::AssertSqlSafe(sql.to_string()))
                .execute(&mut conn)
                .await?;
            Ok(())
        })
}

/// A running `poseboard serve`, killed when dropped.
pub struct Server {
    pub child: Child,
    pub addr: std::net::SocketAddr,
}

impl Server {
    /// Spawns `cmd` (a `poseboard serve --bind 127.0.0.1:0 ...` whose stderr is set) and waits
    /// for the line that tells its address; the rest of its output is drained, so that it never
    /// blocks on a full pipe.
    pub fn spawn(cmd: &mut Command) -> Res<Server> {
        // Built at once, so that a server that fails to start is killed on the way out.
        let mut server = Server {
            child: cmd.stdout(Stdio::piped()).spawn()?,
            addr: ([127, 0, 0, 1], 0).into(),
        };
        let stdout = server.child.stdout.take().ok_or("stdout")?;
        let mut lines = BufReader::new(stdout).lines();
        let line = lines.next().ok_or("the server printed nothing")??;
        std::thread::spawn(move || for _ in lines {});
        server.addr = line
            .strip_prefix("poseboard listening on http://")
            .ok_or_else(|| format!("unexpected first line: {line}"))?
            .parse()?;
        Ok(server)
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
