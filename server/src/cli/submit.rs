//! `poseboard submit`: a result file sent to a poseboard server from the script that wrote it.
//! The file is checked here first with the parser `check-results` uses, so a malformed file
//! fails on the researcher's machine, naming its lines, before a byte is uploaded; then it is
//! uploaded through the API, the evaluation is followed, and the scores are printed the way
//! `poseboard eval` prints them.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{Context, Result, bail};
use clap::Args;
use evaluator::Report;
use evaluator::protocol::ProtocolName;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use reqwest::blocking::{Client, Response, multipart};
use serde_json::Value;

use crate::cli::eval::{load_results, print_scores};
use crate::domain::Visibility;

#[derive(Args, Debug)]
pub struct SubmitArgs {
    /// The result file (BOP'19 CSV, `METHOD_DATASET-SPLIT.csv`).
    pub file: PathBuf,
    /// The method the results are of (created on the server at its first submission).
    #[arg(long)]
    pub method: String,
    /// The dataset the results are for, as the server names it.
    #[arg(long)]
    pub dataset: String,
    /// Evaluate under this protocol only (default: both).
    #[arg(long)]
    pub protocol: Option<ProtocolName>,
    /// Who may see the submission (default: the server's).
    #[arg(long)]
    pub visibility: Option<Visibility>,
    /// The poseboard server.
    #[arg(
        long,
        env = "POSEBOARD_SERVER",
        default_value = "http://127.0.0.1:8080"
    )]
    pub server: String,
    /// A personal API token (made on the server's account page).
    #[arg(long, env = "POSEBOARD_TOKEN", hide_env_values = true)]
    pub token: String,
    /// A PEM certificate to trust as well as the bundled roots: the authority of a server with
    /// a private or self-signed certificate.
    #[arg(long, env = "POSEBOARD_CA_CERT")]
    pub ca_cert: Option<PathBuf>,
    /// Also print the final submission as JSON, as the last line of stdout.
    #[arg(long)]
    pub json: bool,
}

/// How often the submission is looked at while it waits or runs.
const POLL: Duration = Duration::from_millis(500);

pub fn run(args: SubmitArgs) -> Result<()> {
    let results = load_results(&args.file)?;
    eprintln!(
        "{}: {} estimates, valid",
        args.file.display(),
        results.estimates.len()
    );
    let server = args.server.trim_end_matches('/').to_string();
    if !server.starts_with("http://") && !server.starts_with("https://") {
        bail!("{server}: the server's address must start with http:// or https://");
    }
    let mut client = Client::builder()
        .connect_timeout(Duration::from_secs(20))
        // An upload of a large file takes as long as it takes; the server bounds stalls.
        .timeout(None);
    if let Some(path) = &args.ca_cert {
        let pem = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
        let certificate = reqwest::Certificate::from_pem(&pem)
            .with_context(|| format!("{} is not a PEM certificate", path.display()))?;
        client = client.add_root_certificate(certificate);
    }
    let client = client.build().context("cannot start the HTTP client")?;
    reach(&client, &server, &args.token)?;

    let accepted = upload(&client, &server, &args)?;
    let id = accepted["id"]
        .as_i64()
        .context("the server's answer has no submission id")?;
    if accepted["duplicate"].as_bool() == Some(true) {
        eprintln!("submission {id}: this file was submitted before for this method");
    } else {
        eprintln!("submission {id}: queued");
    }

    let done = follow(&client, &server, &args.token, id)?;
    let scores: BTreeMap<ProtocolName, Report> =
        serde_json::from_value(done["scores"].clone()).context("the scores the server sent")?;
    // The order the protocols are named in everywhere else: BOP'19 first.
    for protocol in [ProtocolName::Bop19, ProtocolName::Eccv18] {
        if let Some(report) = scores.get(&protocol) {
            print_scores(report);
        }
    }
    eprintln!("{server}/submissions/{id}");
    if args.json {
        println!("{done}");
    }
    Ok(())
}

/// A first small request, signed with the token, before the file is streamed: a server that
/// cannot be reached, a certificate that is not trusted or a token the server refuses is named
/// as such (a server refusing a streamed upload early is heard only as "send failed"), and a
/// large file is not sent for nothing. The connection is not kept for the upload, for the same
/// reason.
fn reach(client: &Client, server: &str, token: &str) -> Result<()> {
    let response = client
        .get(format!("{server}/api/v1/me/submissions"))
        .bearer_auth(token)
        .header(reqwest::header::CONNECTION, "close")
        .timeout(Duration::from_secs(60))
        .send()
        .with_context(|| format!("cannot reach {server}"))?;
    answer(response).map(drop)
}

/// Sends the file with its fields; the answer's JSON when accepted.
fn upload(client: &Client, server: &str, args: &SubmitArgs) -> Result<Value> {
    let size = std::fs::metadata(&args.file)
        .with_context(|| format!("cannot read {}", args.file.display()))?
        .len();
    let bar = bar(size, "{bar:40} {bytes}/{total_bytes} uploaded  {elapsed}");
    let reader = Counted {
        file: File::open(&args.file)
            .with_context(|| format!("cannot read {}", args.file.display()))?,
        bar: bar.clone(),
    };
    let name = file_name(&args.file);
    let mut form = multipart::Form::new()
        .text("method", args.method.clone())
        .text("dataset", args.dataset.clone())
        .part(
            "file",
            multipart::Part::reader_with_length(reader, size).file_name(name),
        );
    if let Some(p) = args.protocol {
        form = form.text("protocol", p.as_str());
    }
    // Sent only when asked for: without it the server keeps its own default, and a file
    // submitted again keeps the visibility it has.
    if let Some(v) = args.visibility {
        form = form.text("visibility", v.as_str());
    }
    let response = client
        .post(format!("{server}/api/v1/submissions"))
        .bearer_auth(&args.token)
        .multipart(form)
        .send();
    bar.finish_and_clear();
    let response = response.with_context(|| format!("cannot upload to {server}"))?;
    answer(response)
}

/// Polls the submission until it is done (its JSON) or failed (an error with its message).
fn follow(client: &Client, server: &str, token: &str, id: i64) -> Result<Value> {
    let bar = bar(1000, "{spinner} {msg} {bar:30} {elapsed}");
    bar.enable_steady_tick(Duration::from_millis(120));
    let outcome = loop {
        let response = client
            .get(format!("{server}/api/v1/submissions/{id}"))
            .bearer_auth(token)
            .timeout(Duration::from_secs(60))
            .send()
            .with_context(|| format!("cannot reach {server}"));
        let submission = match response.and_then(answer) {
            Ok(s) => s,
            Err(e) => break Err(e),
        };
        match submission["status"].as_str() {
            Some("done") => break Ok(submission),
            Some("failed") => {
                break Err(anyhow::anyhow!(
                    "submission {id} failed: {}",
                    submission["error"].as_str().unwrap_or("no reason given")
                ));
            }
            Some("queued") => bar.set_message(match submission["queue_position"].as_i64() {
                Some(n) => format!("queued (position {n})"),
                None => "queued".to_string(),
            }),
            Some(status) => {
                let progress = submission["progress"].as_f64().unwrap_or(0.0);
                bar.set_position((progress.clamp(0.0, 1.0) * 1000.0) as u64);
                bar.set_message(status.to_string());
            }
            None => break Err(anyhow::anyhow!("the server's answer has no status")),
        }
        std::thread::sleep(POLL);
    };
    bar.finish_and_clear();
    outcome
}

/// The JSON of a successful answer; for any other, an error carrying the server's message and
/// every problem it listed (a line of the file, say).
fn answer(response: Response) -> Result<Value> {
    let status = response.status();
    let text = response.text().context("the server's answer was cut")?;
    let body: Option<Value> = serde_json::from_str(&text).ok();
    if status.is_success() {
        return body.with_context(|| format!("the server answered {status} without JSON"));
    }
    let Some(body) = body else {
        bail!("the server answered {status}: {}", text.trim());
    };
    let mut message = format!(
        "the server answered {status}: {}",
        body["error"].as_str().unwrap_or("no message")
    );
    for p in body["problems"].as_array().into_iter().flatten() {
        message.push_str(&format!(
            "\n  line {}: {}",
            p["line"].as_u64().unwrap_or(0),
            p["message"].as_str().unwrap_or_default()
        ));
    }
    bail!(message)
}

fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "results.csv".to_string())
}

/// A bar on stderr, drawn only when stderr is a terminal (indicatif hides it otherwise).
fn bar(len: u64, template: &str) -> ProgressBar {
    let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr());
    bar.set_style(ProgressStyle::with_template(template).expect("a valid template"));
    bar
}

/// The file being uploaded, counting its bytes into the upload's bar as they are read.
struct Counted {
    file: File,
    bar: ProgressBar,
}

impl Read for Counted {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.file.read(buf)?;
        self.bar.inc(n as u64);
        Ok(n)
    }
}
