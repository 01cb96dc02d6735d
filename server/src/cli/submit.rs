//! `poseboard submit`: a result file sent to a poseboard server from the script that wrote it.
//! The file is checked here first with the parser `check-results` uses, so a malformed file
//! fails on the researcher's machine, naming its lines, before a byte is uploaded; then it is
//! uploaded through the API, the evaluation is followed, and the scores are printed as the
//! site shows them (percent; `--json` keeps the fractions). A researcher's script ends here, so
//! what became of the submission is said after the scores: who sees it, whether it is on a
//! board, what red flag holds it back, and what publishes it.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::Args;
use evaluator::Report;
use evaluator::detection::{self, DetectionReport};
use evaluator::protocol::ProtocolName;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use reqwest::blocking::{Client, Response, multipart};
use serde::Serialize;
use serde_json::Value;

use crate::cli::eval::{Scale, bop24_table, load_results, print_scores_as};
use crate::domain::{TeamName, Visibility};
use crate::preflight::RedFlag;
use crate::service::submissions::file_dataset;

/// What `--protocol` asks for: one localization protocol, or BOP'24 6D detection, which reads
/// the same CSV files.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SubmitProtocol {
    Pose(ProtocolName),
    Bop24,
}

impl SubmitProtocol {
    fn as_str(self) -> &'static str {
        match self {
            SubmitProtocol::Pose(p) => p.as_str(),
            SubmitProtocol::Bop24 => detection::PROTOCOL,
        }
    }
}

impl std::str::FromStr for SubmitProtocol {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            detection::PROTOCOL => Ok(SubmitProtocol::Bop24),
            other => other
                .parse()
                .map(SubmitProtocol::Pose)
                .map_err(|_| format!("unknown protocol `{other}` (bop19, eccv18 or bop24)")),
        }
    }
}

#[derive(Args, Debug)]
pub struct SubmitArgs {
    /// The result file (BOP'19 CSV, `METHOD_DATASET-SPLIT.csv`).
    pub file: PathBuf,
    /// The method the results are of (created on the server at its first submission).
    #[arg(long)]
    pub method: String,
    /// Submit to this team's method of that name (created as the team's if new): for the
    /// team's members; the boards name the team as the owner.
    #[arg(long, value_parser = team_name)]
    pub team: Option<TeamName>,
    /// The dataset the results are for, as the server names it (default: the one the file's
    /// name `METHOD_DATASET-SPLIT.csv` says, as the server reads it).
    #[arg(long)]
    pub dataset: Option<String>,
    /// Evaluate under this protocol only: bop19 or eccv18, or bop24 for 6D detection (the
    /// dataset's test_targets_bop24.json); default: bop19 and eccv18.
    #[arg(long)]
    pub protocol: Option<SubmitProtocol>,
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
    /// Also print the final submission as JSON, as the last line of stdout (its `outcome`
    /// says what the text says after the scores).
    #[arg(long)]
    pub json: bool,
}

/// `--team` as the server reads it, so a name no team can have fails before the upload.
fn team_name(value: &str) -> std::result::Result<TeamName, String> {
    TeamName::parse("team", value).map_err(|e| e.to_string())
}

/// How often the submission is looked at while it waits or runs.
const POLL: Duration = Duration::from_millis(500);

pub fn run(args: SubmitArgs) -> Result<()> {
    let dataset = file_dataset(args.dataset.as_deref(), &file_name(&args.file))
        .map_err(|e| anyhow::anyhow!("{e}"))?;
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

    let accepted = upload(&client, &server, &args, &dataset)?;
    let id = accepted["id"]
        .as_i64()
        .context("the server's answer has no submission id")?;
    if accepted["duplicate"].as_bool() == Some(true) {
        eprintln!("submission {id}: this file was submitted before for this method");
    } else {
        eprintln!("submission {id}: queued");
    }

    let mut done = follow(&client, &server, &args.token, id)?;
    let scores: BTreeMap<ProtocolName, Report> =
        serde_json::from_value(done["scores"].clone()).context("the scores the server sent")?;
    // The order the protocols are named in everywhere else: BOP'19 first.
    for protocol in [ProtocolName::Bop19, ProtocolName::Eccv18] {
        if let Some(report) = scores.get(&protocol) {
            print_scores_as(report, Scale::Percent);
        }
    }
    if !done["bop24"].is_null() {
        let report: DetectionReport =
            serde_json::from_value(done["bop24"].clone()).context("the bop24 scores")?;
        print!("{}", bop24_table(&report));
    }
    let outcome = Outcome::of(&done, &server, &args, &dataset)?;
    print!("{}", outcome.text());
    if args.json {
        done["outcome"] = serde_json::to_value(&outcome).context("the outcome as JSON")?;
        println!("{done}");
    }
    Ok(())
}

/// What became of a finished submission, for the researcher who sent it.
#[derive(Debug, Serialize)]
struct Outcome {
    /// `public`, `private` or `held` (private until its owner confirms despite red flags).
    visibility: &'static str,
    /// The server's words for it ("private: only you ... can see it", "held: ...").
    publication: String,
    /// The protocols under which this submission is the method's entry on the board.
    on_board: Vec<String>,
    /// Per protocol with another entry: that submission (the method's best or pinned one).
    entry_elsewhere: BTreeMap<String, i64>,
    /// Why publication waits for the owner's confirmation.
    red_flags: Vec<String>,
    /// What publishes it, when it is not public.
    publish: Option<String>,
    url: String,
}

impl Outcome {
    fn of(done: &Value, server: &str, args: &SubmitArgs, dataset: &str) -> Result<Outcome> {
        let id = done["id"].as_i64().context("the submission has no id")?;
        let url = format!("{server}/submissions/{id}");
        let red_flags: Vec<RedFlag> =
            serde_json::from_value(done["preflight"]["red_flags"].clone())
                .context("the red flags the server sent")?;
        let held = done["held"].as_bool() == Some(true);
        let visibility = match done["visibility"].as_str() {
            Some("public") => "public",
            _ if held => "held",
            _ => "private",
        };
        let (mut on_board, mut entry_elsewhere) = (Vec::new(), BTreeMap::new());
        for e in done["entries"].as_array().into_iter().flatten() {
            let protocol = e["protocol"].as_str().unwrap_or_default().to_string();
            match e["submission_id"].as_i64() {
                Some(other) if other != id => {
                    entry_elsewhere.insert(protocol, other);
                }
                _ => on_board.push(protocol),
            }
        }
        let publish = match visibility {
            "public" => None,
            _ if !red_flags.is_empty() => Some(format!(
                "confirm on {url} (\"Confirm and publish despite the red flags\"), or POST \
                 {server}/api/v1/submissions/{id}/visibility with visibility=public&confirm=true"
            )),
            _ => {
                // The same command with the visibility asked for: a file sent again for its
                // method is how its owner publishes it.
                let mut again = format!(
                    "poseboard submit {} --method {}",
                    args.file.display(),
                    args.method
                );
                if let Some(team) = &args.team {
                    again.push_str(&format!(" --team {team}"));
                }
                if args.dataset.is_some() {
                    again.push_str(&format!(" --dataset {dataset}"));
                }
                if let Some(p) = args.protocol {
                    again.push_str(&format!(" --protocol {}", p.as_str()));
                }
                Some(format!(
                    "`{again} --visibility public` (the same file again), or the Publish \
                     button on {url}"
                ))
            }
        };
        Ok(Outcome {
            visibility,
            publication: done["publication"].as_str().unwrap_or_default().to_string(),
            on_board,
            entry_elsewhere,
            red_flags: red_flags.iter().map(RedFlag::to_string).collect(),
            publish,
            url,
        })
    }

    /// The outcome in lines, as printed after the scores: who sees it and what publishes it
    /// first, then its red flags and where it stands on the boards.
    fn text(&self) -> String {
        let mut s = match (self.visibility, &self.publish) {
            ("public", _) | (_, None) => format!("{}\n", self.publication),
            ("held", Some(how)) => format!(
                "held: private until you confirm publishing it despite its red flags; to \
                 publish anyway, {how}\n"
            ),
            (_, Some(how)) if self.red_flags.is_empty() => {
                format!("private: only you see it; publish with {how}\n")
            }
            (_, Some(how)) => format!(
                "private: only you see it; its red flags hold publication back: to publish \
                 anyway, {how}\n"
            ),
        };
        for flag in &self.red_flags {
            s.push_str(&format!("red flag: {flag}\n"));
        }
        for p in &self.on_board {
            s.push_str(&format!(
                "on the {p} board: this is the method's entry on the dataset\n"
            ));
        }
        for (p, other) in &self.entry_elsewhere {
            s.push_str(&format!(
                "not on the {p} board: the method's entry there is submission {other}\n"
            ));
        }
        if self.visibility != "public" {
            s.push_str("not on a board: only public submissions are\n");
        }
        s.push_str(&format!("{}\n", self.url));
        s
    }
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
fn upload(client: &Client, server: &str, args: &SubmitArgs, dataset: &str) -> Result<Value> {
    let started = Instant::now();
    loop {
        let response = send_file(client, server, args, dataset)?;
        match unavailable(&response) {
            Some(wait) if started.elapsed() < PATIENCE => {
                eprintln!(
                    "the server's database is unavailable for a moment: sending again in {} s",
                    wait.as_secs()
                );
                std::thread::sleep(wait);
            }
            _ => return accepted(client, server, args, dataset, response),
        }
    }
}

/// How long `submit` waits out a server whose database is unavailable (`503`) before giving
/// up: a restarting or failing-over database is back within this.
const PATIENCE: Duration = Duration::from_secs(120);

/// The wait a `503` asks for (its `Retry-After`, within 1 to 30 s); `None` for other answers.
fn unavailable(response: &Response) -> Option<Duration> {
    (response.status() == reqwest::StatusCode::SERVICE_UNAVAILABLE).then(|| {
        let secs = response
            .headers()
            .get(reqwest::header::RETRY_AFTER)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.trim().parse::<u64>().ok())
            .unwrap_or(2);
        Duration::from_secs(secs.clamp(1, 30))
    })
}

/// One sending of the file with its fields. Sending again after a `503` is safe: nothing was
/// stored, and a file the server has already is answered with its submission, not a new one.
fn send_file(client: &Client, server: &str, args: &SubmitArgs, dataset: &str) -> Result<Response> {
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
        .text("dataset", dataset.to_string())
        .part(
            "file",
            multipart::Part::reader_with_length(reader, size).file_name(name),
        );
    if let Some(p) = args.protocol {
        form = form.text("protocol", p.as_str());
    }
    if let Some(team) = &args.team {
        form = form.text("team", team.to_string());
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
    response.with_context(|| format!("cannot upload to {server}"))
}

/// The upload's answer: its JSON when accepted, else the server's reasons.
fn accepted(
    client: &Client,
    server: &str,
    args: &SubmitArgs,
    dataset: &str,
    response: Response,
) -> Result<Value> {
    let over_limit = response.status() == reqwest::StatusCode::TOO_MANY_REQUESTS;
    let answered = answer(response);
    match answered {
        // Over the fair-use limit: what is left on the dataset, as the upload form shows it.
        Err(refused) if over_limit => match quota(client, server, &args.token, dataset) {
            Ok(left) => Err(anyhow::anyhow!("{refused}\n{dataset}: {left}")),
            Err(_) => Err(refused),
        },
        answered => answered,
    }
}

/// The caller's quota on `dataset` in words ("none left today: the next at ...").
fn quota(client: &Client, server: &str, token: &str, dataset: &str) -> Result<String> {
    let response = client
        .get(format!("{server}/api/v1/me/quota"))
        .query(&[("dataset", dataset)])
        .bearer_auth(token)
        .timeout(Duration::from_secs(60))
        .send()
        .with_context(|| format!("cannot reach {server}"))?;
    let quota = answer(response)?;
    quota["summary"]
        .as_str()
        .map(str::to_string)
        .context("the server's quota has no summary")
}

/// Polls the submission until it is done (its JSON) or failed (an error with its message).
fn follow(client: &Client, server: &str, token: &str, id: i64) -> Result<Value> {
    let bar = bar(1000, "{spinner} {msg} {bar:30} {elapsed}");
    bar.enable_steady_tick(Duration::from_millis(120));
    // Since when the server has answered `503` without a break.
    let mut unanswered: Option<Instant> = None;
    let outcome = loop {
        let response = client
            .get(format!("{server}/api/v1/submissions/{id}"))
            .bearer_auth(token)
            .timeout(Duration::from_secs(60))
            .send()
            .with_context(|| format!("cannot reach {server}"));
        if let Ok(r) = &response
            && let Some(wait) = unavailable(r)
            && unanswered.get_or_insert_with(Instant::now).elapsed() < PATIENCE
        {
            bar.set_message("the server's database is unavailable for a moment");
            std::thread::sleep(wait);
            continue;
        }
        unanswered = None;
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
