//! Slow and silent clients, over real TCP against `poseboard serve`: a socket that sends half a
//! header, or nothing, is closed by the server after the configured timeouts, so such sockets
//! cannot exhaust its descriptors (a server held to 64 descriptors still answers after 60 of
//! them); an upload that keeps making progress completes however long it takes, past the
//! plain request timeout; and one that stalls is refused with 408 naming the pace it must
//! keep. The timeouts are set short through the environment. Connection handling does not
//! depend on the database, so these run on SQLite only.

use std::io::{ErrorKind, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use crate::common::{Db, Server, TestDb, client, fixtures, reference_datasets, start_with_env};
use reqwest::blocking::multipart;
use serde_json::Value;

/// Headers and idle connections: 1 s; a plain request: 1 s; an upload: 8 KiB every 2 s.
const SHORT: &[(&str, &str)] = &[
    ("POSEBOARD_HEADER_TIMEOUT_SECS", "1"),
    ("POSEBOARD_IDLE_TIMEOUT_SECS", "1"),
    ("POSEBOARD_REQUEST_TIMEOUT_SECS", "1"),
    ("POSEBOARD_UPLOAD_MIN_KIB", "8"),
    ("POSEBOARD_UPLOAD_WINDOW_SECS", "2"),
];

/// How long a test waits for the server before calling it stuck (far above every timeout).
const PATIENCE: Duration = Duration::from_secs(30);

fn serve(dir: &Path) -> (Server, TestDb) {
    let datasets = reference_datasets(dir);
    let db = TestDb::new(Db::Sqlite, "conn");
    let server = start_with_env(&dir.join("data"), &datasets, &db, &[], SHORT);
    (server, db)
}

fn address(server: &Server) -> String {
    server
        .base
        .strip_prefix("http://")
        .expect("http address")
        .to_string()
}

/// Reads until the server closes the socket and returns what it sent; panics if it is still
/// open after [`PATIENCE`].
fn read_until_closed(mut socket: TcpStream, what: &str) -> Vec<u8> {
    socket.set_read_timeout(Some(PATIENCE)).expect("timeout");
    let mut got = Vec::new();
    match socket.read_to_end(&mut got) {
        Ok(_) => got,
        Err(e) if e.kind() == ErrorKind::ConnectionReset => got,
        Err(e) => panic!("{what}: still open after {PATIENCE:?} ({e})"),
    }
}

#[test]
fn half_headers_and_silent_sockets_are_closed() {
    let dir = tempfile::tempdir().expect("tmp");
    let (server, _db) = serve(dir.path());
    let addr = address(&server);
    let mut half = TcpStream::connect(&addr).expect("connect");
    half.write_all(b"GET /api/v1/datasets HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: ")
        .expect("half a header");
    let silent = TcpStream::connect(&addr).expect("connect");
    // A keep-alive connection is answered, then closed once it idles.
    let mut kept = TcpStream::connect(&addr).expect("connect");
    kept.write_all(b"GET /api/v1/datasets HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
        .expect("a request");
    read_until_closed(half, "a socket that sent half a header");
    read_until_closed(silent, "a socket that sent nothing");
    let answer = read_until_closed(kept, "an idle keep-alive connection");
    assert!(
        answer.starts_with(b"HTTP/1.1 200"),
        "{}",
        String::from_utf8_lossy(&answer)
    );
    // The server still answers.
    let r = client()
        .get(format!("{}/api/v1/datasets", server.base))
        .send()
        .expect("answered");
    assert_eq!(r.status(), 200);
}

#[test]
fn stalled_sockets_cannot_exhaust_the_descriptors() {
    let dir = tempfile::tempdir().expect("tmp");
    let (server, _db) = serve(dir.path());
    let addr = address(&server);
    // The server may hold 64 descriptors (its database, log and listener among them).
    let status = Command::new("prlimit")
        .arg(format!("--pid={}", server.child.id()))
        .arg("--nofile=64:64")
        .status()
        .expect("prlimit runs");
    assert!(status.success());
    let sockets: Vec<TcpStream> = (0..60)
        .map(|_| {
            let mut s = TcpStream::connect(&addr).expect("connect");
            s.write_all(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n")
                .expect("half a header");
            s
        })
        .collect();
    for (i, s) in sockets.into_iter().enumerate() {
        read_until_closed(s, &format!("half-header socket {i}"));
    }
    let r = client()
        .get(format!("{}/api/v1/datasets", server.base))
        .send()
        .expect("answered");
    assert_eq!(r.status(), 200);
}

/// A valid result file of about `rows` lines for the reference dataset (its estimates
/// repeated with other scores), named `name`.
fn big_result_file(dir: &Path, name: &str, rows: usize) -> PathBuf {
    let text = std::fs::read_to_string(fixtures().join("results/gtexact_synthA-test.csv"))
        .expect("fixture");
    let mut lines = text.lines();
    let header = lines.next().expect("header");
    let estimates: Vec<&str> = lines.collect();
    let mut out = format!("{header}\n");
    for i in 0..rows {
        let fields: Vec<&str> = estimates[i % estimates.len()].split(',').collect();
        let score = format!("{:.6}", 0.5 + (i % 1000) as f64 / 10_000.0);
        out.push_str(
            &[&fields[..3], &[score.as_str()], &fields[4..]]
                .concat()
                .join(","),
        );
        out.push('\n');
    }
    let path = dir.join(name);
    std::fs::write(&path, out).expect("write");
    path
}

/// A reader that hands out `chunk` bytes at a time, pausing `pause` before each.
struct Slow {
    data: Vec<u8>,
    at: usize,
    chunk: usize,
    pause: Duration,
}

impl Read for Slow {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.at == self.data.len() {
            return Ok(0);
        }
        std::thread::sleep(self.pause);
        let n = self.chunk.min(buf.len()).min(self.data.len() - self.at);
        buf[..n].copy_from_slice(&self.data[self.at..self.at + n]);
        self.at += n;
        Ok(n)
    }
}

#[test]
fn a_slow_upload_that_keeps_progressing_completes() {
    let dir = tempfile::tempdir().expect("tmp");
    let (server, _db) = serve(dir.path());
    let file = big_result_file(dir.path(), "slow_synthA-test.csv", 1000);
    let data = std::fs::read(&file).expect("read");
    // 16 KiB every 150 ms: twice the required 8 KiB per 2 s in every window, for about three
    // times the plain 1-s timeout.
    let chunks = data.len().div_ceil(16 * 1024);
    assert!(chunks >= 15, "{} bytes", data.len());
    let body = Slow {
        data,
        at: 0,
        chunk: 16 * 1024,
        pause: Duration::from_millis(150),
    };
    let form = multipart::Form::new()
        .text("method", "patient")
        .text("dataset", "synthA")
        .part(
            "file",
            multipart::Part::reader(body).file_name("slow_synthA-test.csv"),
        );
    let r = client()
        .post(format!("{}/api/v1/submissions", server.base))
        .bearer_auth(&server.token)
        .multipart(form)
        .send()
        .expect("answered");
    let status = r.status();
    let body: Value = r.json().expect("json");
    assert_eq!(status, 202, "{body}");
    assert_eq!(body["submission"]["estimates_count"], 1000);
}

#[test]
fn a_stalled_upload_is_cut_with_408() {
    let dir = tempfile::tempdir().expect("tmp");
    let (server, _db) = serve(dir.path());
    let mut socket = TcpStream::connect(address(&server)).expect("connect");
    let start = "--XyZ\r\nContent-Disposition: form-data; name=\"method\"\r\n\r\nstuck\r\n\
                 --XyZ\r\nContent-Disposition: form-data; name=\"file\"; filename=\"stuck_synthA-test.csv\"\r\n\r\n\
                 scene_id,im_id,obj_id,score,R,t,time\r\n";
    let head = format!(
        "POST /api/v1/submissions HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer {}\r\n\
         Content-Type: multipart/form-data; boundary=XyZ\r\nContent-Length: 100000\r\n\r\n{start}",
        server.token
    );
    socket.write_all(head.as_bytes()).expect("a beginning");
    // Then nothing more.
    let answer =
        String::from_utf8_lossy(&read_until_closed(socket, "a stalled upload")).to_string();
    assert!(answer.starts_with("HTTP/1.1 408"), "{answer}");
    assert!(
        answer.contains("at least 8 KiB every 2 s"),
        "the answer states the pace: {answer}"
    );
    // Nothing was submitted (the uploader's own list holds every state, private included).
    let recent: Value = client()
        .get(format!("{}/api/v1/me/submissions", server.base))
        .bearer_auth(&server.token)
        .send()
        .expect("answered")
        .json()
        .expect("json");
    assert_eq!(recent["submissions"].as_array().map(Vec::len), Some(0));
}
