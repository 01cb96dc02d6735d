//! The container setup, checked without a Docker engine: `docker-compose.yml` names PostgreSQL,
//! one server and a worker service that `--scale worker=N` can multiply; its commands are ones
//! the `poseboard` command line accepts; the Dockerfile builds in stages and runs the binary as
//! an unprivileged user.

use std::path::{Path, PathBuf};

use clap::Parser;
use serde_norway::Value;
use server::cli::{Cli, Command};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn compose() -> Value {
    let text = std::fs::read_to_string(repo().join("docker-compose.yml")).expect("compose file");
    serde_norway::from_str(&text).expect("docker-compose.yml is YAML")
}

/// A list of strings in the YAML.
fn strings(v: &Value) -> Vec<String> {
    v.as_sequence()
        .unwrap_or_else(|| panic!("a list: {v:?}"))
        .iter()
        .map(|s| s.as_str().expect("a string").to_string())
        .collect()
}

/// The command line a container runs: the image's entrypoint, then the service's command.
fn parse(command: &[String]) -> Command {
    let argv = std::iter::once("poseboard".to_string()).chain(command.iter().cloned());
    Cli::try_parse_from(argv)
        .unwrap_or_else(|e| panic!("`poseboard {}` is refused: {e}", command.join(" ")))
        .command
}

/// The stages of the Dockerfile: (name, base image, instructions), continuation lines joined.
fn stages() -> Vec<(String, String, Vec<String>)> {
    let text = std::fs::read_to_string(repo().join("Dockerfile")).expect("Dockerfile");
    let mut lines = Vec::new();
    let mut current = String::new();
    for line in text.lines() {
        let line = line.trim();
        if line.starts_with('#') || (line.is_empty() && current.is_empty()) {
            continue;
        }
        match line.strip_suffix('\\') {
            Some(head) => current.push_str(head),
            None => {
                current.push_str(line);
                lines.push(std::mem::take(&mut current));
            }
        }
    }
    let mut stages: Vec<(String, String, Vec<String>)> = Vec::new();
    for line in lines {
        let words: Vec<&str> = line.split_whitespace().collect();
        if words
            .first()
            .is_some_and(|w| w.eq_ignore_ascii_case("FROM"))
        {
            let name = match words.as_slice() {
                [_, _, as_, name] if as_.eq_ignore_ascii_case("AS") => name.to_string(),
                _ => String::new(),
            };
            stages.push((name, words[1].to_string(), Vec::new()));
        } else if let Some(stage) = stages.last_mut() {
            stage.2.push(line);
        }
    }
    stages
}

#[test]
fn compose_names_postgres_a_server_and_workers_that_scale() {
    let compose = compose();
    let services = compose["services"].as_mapping().expect("services");
    let names: Vec<&str> = services.keys().filter_map(Value::as_str).collect();
    for name in ["postgres", "server", "worker"] {
        assert!(names.contains(&name), "no service {name}: {names:?}");
    }
    let (server, worker) = (
        &compose["services"]["server"],
        &compose["services"]["worker"],
    );
    assert!(
        compose["services"]["postgres"]["image"]
            .as_str()
            .is_some_and(|i| i.starts_with("postgres:"))
    );

    assert!(
        matches!(parse(&strings(&server["command"])), Command::Serve(_)),
        "the server serves"
    );
    assert!(
        matches!(parse(&strings(&worker["command"])), Command::Worker(_)),
        "the worker works"
    );

    // Copies of a service cannot share a host port or a container name.
    assert!(worker.get("ports").is_none(), "a worker publishes no port");
    assert!(worker.get("container_name").is_none());
    // The server's published port is the one it listens on.
    let bind = server["environment"]["POSEBOARD_BIND"]
        .as_str()
        .expect("bind");
    let port = bind.rsplit(':').next().expect("port");
    assert!(
        strings(&server["ports"])
            .iter()
            .any(|p| p.ends_with(&format!(":{port}"))),
        "the server publishes {port}"
    );

    for (name, service) in [("server", server), ("worker", worker)] {
        let url = service["environment"]["DATABASE_URL"]
            .as_str()
            .expect("a database URL");
        assert!(
            url.starts_with("postgres://") && url.contains("@postgres:"),
            "{name} uses the postgres service: {url}"
        );
        assert!(service["depends_on"]["postgres"].is_mapping(), "{name}");
        assert_eq!(service["build"]["context"].as_str(), Some("."), "{name}");
        assert_eq!(service["image"], server["image"], "{name}: one image");
        assert!(
            strings(&service["volumes"])
                .iter()
                .any(|v| v.ends_with(":/datasets:ro")),
            "{name} reads the datasets from a read-only volume"
        );
        // The build target is a stage of the Dockerfile.
        let target = service["build"]["target"].as_str().expect("target");
        assert!(stages().iter().any(|(n, _, _)| n == target), "{target}");
    }
    // Workers keep nothing: the uploads reach them through PostgreSQL.
    assert_eq!(
        strings(&worker["volumes"]).len(),
        1,
        "the worker mounts only the datasets"
    );
}

#[test]
fn the_dockerfile_builds_in_stages_and_runs_unprivileged() {
    let stages = stages();
    assert!(stages.len() >= 2, "multi-stage: {stages:?}");
    let (builder, base, steps) = &stages[0];
    assert!(
        base.starts_with("rust:"),
        "built with the Rust image: {base}"
    );
    assert!(
        steps
            .iter()
            .any(|s| s.contains("cargo build --release --locked") && s.contains("poseboard")),
        "builds the poseboard binary"
    );

    let (_, base, steps) = stages.last().expect("final stage");
    assert_eq!(base, "debian:bookworm-slim", "a small runtime image");
    assert!(
        steps.iter().any(|s| s.starts_with("COPY")
            && s.contains(&format!("--from={builder}"))
            && s.contains("poseboard")),
        "the final stage takes the binary from the builder"
    );
    let users: Vec<&String> = steps.iter().filter(|s| s.starts_with("USER ")).collect();
    let user = users.last().expect("a USER instruction");
    let who = user["USER ".len()..].split(':').next().expect("user");
    assert!(
        who != "root" && who != "0" && !who.is_empty(),
        "runs as a non-root user: {user}"
    );
    // ENTRYPOINT and CMD in exec form: signals reach poseboard, not a shell.
    let json = |instr: &str| -> Vec<String> {
        let line = steps
            .iter()
            .rfind(|s| s.starts_with(instr))
            .unwrap_or_else(|| panic!("no {instr}"));
        serde_json::from_str(line[instr.len()..].trim()).expect("exec form")
    };
    let entrypoint = json("ENTRYPOINT");
    assert!(entrypoint.len() == 1 && entrypoint[0].ends_with("/poseboard"));
    assert!(matches!(parse(&json("CMD")), Command::Serve(_)));
}
