//! `poseboard submit` run as a researcher runs it, against the real server: it prints the
//! scores `poseboard eval` computes for the same file, in percent as the site shows them (and
//! the final submission as JSON on its last line, with the fractions), then what became of the
//! submission (who sees it, the boards, red flags, what publishes it); it takes the dataset
//! from the file's BOP name as the API does, refuses a malformed file before uploading
//! anything, and fails with the server's own message when the server refuses. One database is enough here: the CLI only speaks HTTP,
//! and the store is tested on both elsewhere.

use std::path::Path;
use std::process::{Command, Output, Stdio};

use crate::common::{
    BIN, Db, Server, TestDb, cli_report, client, column, fixtures, get_as, reference_datasets,
    start,
};
use evaluator::Report;
use serde_json::Value;
use server::cli::eval::{Scale, table_as};

/// `poseboard submit FILE` for the method `cli` on `synthA`, with `extra` arguments; the token
/// comes from the environment like a script's would.
fn submit(server: &Server, token: &str, file: &Path, extra: &[&str]) -> Output {
    submit_as(
        server,
        token,
        file,
        &["--method", "cli", "--dataset", "synthA"],
        extra,
    )
}

/// `poseboard submit FILE` with the method and dataset arguments `naming` and `extra` ones.
fn submit_as(server: &Server, token: &str, file: &Path, naming: &[&str], extra: &[&str]) -> Output {
    Command::new(BIN)
        .arg("submit")
        .arg(file)
        .args(naming)
        .args(extra)
        .env("POSEBOARD_SERVER", &server.base)
        .env("POSEBOARD_TOKEN", token)
        .stdin(Stdio::null())
        .output()
        .expect("poseboard submit runs")
}

fn submissions_in_database(db: &TestDb, data: &Path) -> String {
    column(db, data, "SELECT CAST(COUNT(*) AS TEXT) FROM submissions").concat()
}

#[test]
fn submit_prints_the_scores_eval_computes_in_percent() {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(Db::Sqlite, "submit_cli");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    let file = fixtures().join("results/noisemedium_synthA-test.csv");

    let out = submit(&server, &server.token, &file, &["--json"]);
    let stdout = String::from_utf8(out.stdout).expect("utf-8");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "submit failed: {stderr}");

    // The last line is the submission as the server has it, with its id and scores.
    let synth_a = datasets.join("synthA");
    let last = stdout.lines().last().expect("a last line");
    let printed: Value = serde_json::from_str(last).expect("the last line is JSON");
    let id = printed["id"].as_i64().expect("an id");
    assert_eq!(printed["status"], "done");
    let on_server: Value = get_as(
        &format!("{}/api/v1/submissions/{id}", server.base),
        &server.token,
    )
    .json()
    .expect("json");
    assert_eq!(printed["scores"], on_server["scores"]);
    for protocol in ["bop19", "eccv18"] {
        let report = cli_report(&synth_a, &file, protocol);
        for key in [
            "bop19_average_recall",
            "bop19_average_recall_vsd",
            "bop19_average_recall_mssd",
            "bop19_average_recall_mspd",
            "obj_average_recalls",
            "localization",
        ] {
            assert_eq!(
                printed["scores"][protocol][key], report[key],
                "{protocol} {key}"
            );
        }
        // The tables, as `poseboard eval` prints them on the same file and dataset, with the
        // scores in percent.
        let report: Report = serde_json::from_value(report).expect("a report");
        let table = table_as(&report, Scale::Percent);
        assert!(
            stdout.contains(&table),
            "submit's output lacks the {protocol} table:\n{table}\n--- submit printed:\n{stdout}"
        );
    }
    // In percent as the submission's page shows them.
    let page = get_as(&format!("{}/submissions/{id}", server.base), &server.token)
        .text()
        .expect("page");
    let ar = format!(
        "{:.1}",
        printed["scores"]["bop19"]["bop19_average_recall"]
            .as_f64()
            .expect("AR")
            * 100.0
    );
    assert!(
        page.contains(&format!("<td class=\"strong\">{ar}</td>")),
        "{page}"
    );
    assert!(stdout.contains(&format!("AR {ar}   AR_VSD")), "{stdout}");

    // The same over https, through a TLS front whose self-signed certificate only `--ca-cert`
    // vouches for: refused without it, the same submission and tables with it.
    let front = TlsFront::start(&server.base, dir.path());
    let out = submit(&server, &server.token, &file, &["--server", &front.url]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "an unknown certificate was trusted");
    assert!(
        stderr.contains(&format!("cannot reach {}", front.url)) && stderr.contains("certificate"),
        "{stderr}"
    );
    let ca = front.certificate.to_str().expect("utf-8 path");
    let out = submit(
        &server,
        &server.token,
        &file,
        &["--server", &front.url, "--ca-cert", ca, "--json"],
    );
    let over_tls = String::from_utf8(out.stdout).expect("utf-8");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let again: Value =
        serde_json::from_str(over_tls.lines().last().expect("a last line")).expect("JSON");
    assert_eq!(
        again["id"], printed["id"],
        "the same file for the same method"
    );
    assert_eq!(again["scores"], printed["scores"]);
    assert!(
        over_tls.contains(&format!("AR {ar}   AR_VSD")),
        "{over_tls}"
    );
}

/// An https:// address in front of the plain-HTTP test server, as a reverse proxy terminating
/// TLS would be: a certificate for 127.0.0.1 signed by nobody the bundled roots know, and the
/// decrypted bytes passed through to the server.
struct TlsFront {
    url: String,
    /// The certificate, PEM, as an operator would hand it out.
    certificate: std::path::PathBuf,
    _runtime: tokio::runtime::Runtime,
}

impl TlsFront {
    fn start(backend: &str, dir: &Path) -> TlsFront {
        use std::sync::Arc;
        use tokio_rustls::rustls::{self, pki_types::PrivateKeyDer};

        let backend = backend.trim_start_matches("http://").to_string();
        let issued = rcgen::generate_simple_self_signed(vec!["127.0.0.1".to_string()])
            .expect("a certificate");
        let certificate = dir.join("front.pem");
        std::fs::write(&certificate, issued.cert.pem()).expect("write the certificate");
        let config = rustls::ServerConfig::builder_with_provider(Arc::new(
            rustls::crypto::ring::default_provider(),
        ))
        .with_safe_default_protocol_versions()
        .expect("TLS versions")
        .with_no_client_auth()
        .with_single_cert(
            vec![issued.cert.der().clone()],
            PrivateKeyDer::Pkcs8(issued.signing_key.serialize_der().into()),
        )
        .expect("a server configuration");
        let acceptor = tokio_rustls::TlsAcceptor::from(Arc::new(config));
        let runtime = tokio::runtime::Runtime::new().expect("a runtime");
        let listener = runtime
            .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
            .expect("a port");
        let url = format!("https://{}", listener.local_addr().expect("address"));
        runtime.spawn(async move {
            while let Ok((socket, _)) = listener.accept().await {
                let (acceptor, backend) = (acceptor.clone(), backend.clone());
                tokio::spawn(async move {
                    // A client that refuses the certificate ends the handshake: nothing to pass.
                    let Ok(mut tls) = acceptor.accept(socket).await else {
                        return;
                    };
                    if let Ok(mut plain) = tokio::net::TcpStream::connect(&backend).await {
                        let _ = tokio::io::copy_bidirectional(&mut tls, &mut plain).await;
                    }
                });
            }
        });
        TlsFront {
            url,
            certificate,
            _runtime: runtime,
        }
    }
}

#[test]
fn a_malformed_file_is_refused_before_any_upload() {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(Db::Sqlite, "submit_cli");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    for (file, message) in [
        (
            "wrong-columns_synthA-test.csv",
            "line 6 has 6 fields, expected 7",
        ),
        ("nan_synthA-test.csv", "non-finite number on line 4"),
        (
            "not-rotation_synthA-test.csv",
            "R on line 5 is not a rotation matrix",
        ),
        ("bad-header_synthA-test.csv", "bad header on line 1"),
    ] {
        let path = fixtures().join("results/malformed").join(file);
        let out = submit(&server, &server.token, &path, &["--json"]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{file} was accepted");
        assert!(stderr.contains(message), "{file}: {stderr}");
        assert!(out.stdout.is_empty(), "{file}: printed a submission");
    }
    assert_eq!(submissions_in_database(&db, &data), "0");
    // The request traces name every request the server saw (the one made below as well): no
    // upload among them.
    let traced = |method: &str, path: &str| {
        std::fs::read_to_string(data.join("server.log"))
            .expect("server log")
            .lines()
            .any(|l| l.contains(method) && l.contains(path))
    };
    assert!(
        !traced("POST", "/api/v1/submissions"),
        "an upload reached the server"
    );
    get_as(&format!("{}/api/v1/datasets", server.base), "");
    assert!(traced("GET", "/api/v1/datasets"), "requests are not traced");
}

#[test]
fn a_refused_upload_fails_with_the_servers_message() {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(Db::Sqlite, "submit_cli");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    let file = fixtures().join("results/noisesmall_synthA-test.csv");

    // What the server says to a token it does not know.
    let said: Value = client()
        .post(format!("{}/api/v1/submissions", server.base))
        .bearer_auth("not-a-token")
        .send()
        .expect("answered")
        .json()
        .expect("a JSON error");
    let message = said["error"].as_str().expect("a message");
    let out = submit(&server, "not-a-token", &file, &["--json"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains(message), "{stderr}");
    assert!(stderr.contains("401"), "{stderr}");

    // A dataset the server does not serve: refused by the server, with its reason (a file
    // named for another dataset than `--dataset` is refused before, see below).
    let nosuch = dir.path().join("cli_nosuch-test.csv");
    std::fs::copy(&file, &nosuch).expect("copy");
    let out = Command::new(BIN)
        .arg("submit")
        .arg(&nosuch)
        .args(["--method", "cli", "--dataset", "nosuch"])
        .args(["--server", &server.base, "--token", &server.token])
        .env_remove("POSEBOARD_SERVER")
        .env_remove("POSEBOARD_TOKEN")
        .output()
        .expect("runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains(
            "the server answered 400 Bad Request: unknown dataset `nosuch` (from the field \
             `dataset`): this server serves synthA"
        ),
        "{stderr}"
    );
    assert_eq!(submissions_in_database(&db, &data), "0");

    // No server at all.
    let out = Command::new(BIN)
        .arg("submit")
        .arg(&file)
        .args(["--method", "cli", "--dataset", "synthA"])
        .args(["--server", "http://127.0.0.1:9", "--token", "t"])
        .output()
        .expect("runs");
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("cannot reach http://127.0.0.1:9"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The outcome `--json` adds to the submission, after checking that the run succeeded; and
/// what the run printed.
fn outcome(out: Output) -> (Value, String) {
    let stdout = String::from_utf8(out.stdout).expect("utf-8");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let last: Value =
        serde_json::from_str(stdout.lines().last().expect("a last line")).expect("JSON");
    (last, stdout)
}

#[test]
fn submit_says_what_became_of_the_submission() {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(Db::Sqlite, "submit_cli");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    let file = fixtures().join("results/noisesmall_synthA-test.csv");
    let naming = ["--method", "plain"];

    // A plain upload, its dataset read from the file's name: private, and how to publish it.
    let (last, stdout) = outcome(submit_as(
        &server,
        &server.token,
        &file,
        &naming,
        &["--json"],
    ));
    let id = last["id"].as_i64().expect("an id");
    assert_eq!(last["dataset"], "synthA");
    let publish = format!(
        "`poseboard submit {} --method plain --visibility public`",
        file.display()
    );
    assert!(
        stdout.contains(&format!("private: only you see it; publish with {publish}")),
        "{stdout}"
    );
    assert!(stdout.contains("not on a board"), "{stdout}");
    let url = format!("{}/submissions/{id}", server.base);
    assert!(stdout.contains(&url), "{stdout}");
    let o = &last["outcome"];
    assert_eq!(o["visibility"], "private");
    assert_eq!(o["on_board"], serde_json::json!([]));
    assert_eq!(o["red_flags"], serde_json::json!([]));
    assert!(
        o["publish"].as_str().expect("how").contains(&publish),
        "{o}"
    );
    // The scores in the JSON stay fractions.
    let ar = last["scores"]["bop19"]["bop19_average_recall"]
        .as_f64()
        .expect("AR");
    assert!((0.0..=1.0).contains(&ar), "{ar}");

    // The command it names publishes it: now on both boards.
    let (last, stdout) = outcome(submit_as(
        &server,
        &server.token,
        &file,
        &naming,
        &["--visibility", "public", "--json"],
    ));
    assert_eq!(last["id"], id);
    let o = &last["outcome"];
    assert_eq!(o["visibility"], "public");
    assert_eq!(o["on_board"], serde_json::json!(["bop19", "eccv18"]));
    assert_eq!(o["publish"], Value::Null);
    assert!(
        stdout.contains("on the bop19 board: this is the method's entry on the dataset"),
        "{stdout}"
    );
    assert!(!stdout.contains("publish with"), "{stdout}");

    // A file in metres asked to be public: held, with its red flag and what publishes it.
    let metres = crate::publishing::in_metres(dir.path());
    let (last, stdout) = outcome(submit_as(
        &server,
        &server.token,
        &metres,
        &["--method", "metres"],
        &["--visibility", "public", "--json"],
    ));
    let held = last["id"].as_i64().expect("an id");
    let o = &last["outcome"];
    assert_eq!(o["visibility"], "held");
    assert_eq!(o["on_board"], serde_json::json!([]));
    assert!(
        o["red_flags"][0]
            .as_str()
            .expect("a flag")
            .starts_with("translations look like metres"),
        "{o}"
    );
    assert!(
        stdout.contains("held: private until you confirm publishing it despite its red flags"),
        "{stdout}"
    );
    assert!(
        stdout.contains("red flag: translations look like metres"),
        "{stdout}"
    );
    assert!(
        stdout.contains(&format!(
            "to publish anyway, confirm on {}/submissions/{held}",
            server.base
        )),
        "{stdout}"
    );

    // A file named for another dataset than the one given is refused before any upload, as
    // the API refuses it; a name that says no dataset needs `--dataset`.
    let other = dir.path().join("plain_synthB-test.csv");
    std::fs::copy(&file, &other).expect("copy");
    let out = submit(&server, &server.token, &other, &[]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("is named for dataset `synthB`, but the field `dataset` says `synthA`"),
        "{stderr}"
    );
    let unnamed = dir.path().join("results.csv");
    std::fs::copy(&file, &unnamed).expect("copy");
    let out = submit_as(&server, &server.token, &unnamed, &naming, &[]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("METHOD_DATASET-SPLIT.csv"), "{stderr}");
    assert_eq!(submissions_in_database(&db, &data), "2");
}
