//! Leaderboard exports and reproducibility records (issue 14), over real HTTP on both
//! databases, one server each: with several methods on the board, the CSV, JSON and LaTeX
//! exports hold every row of the board JSON with the same names and scores; the LaTeX is one
//! complete, balanced `tabular` whose rows all have as many cells as it has columns and whose
//! bold cells are exactly the best of each column; every score carries its record (evaluator
//! version, protocol and parameters as the protocol defines them, dataset content hash, result
//! file SHA-256) equal to what the store holds and to the hash of the uploaded bytes; and the
//! exports follow a withdrawal at once.

use std::collections::BTreeMap;

use crate::common::{
    Db, TestDb, both_databases, client, column, fixtures, get_json, reference_datasets, start,
    upload, wait_done,
};
use serde_json::Value;
use sha2::{Digest, Sha256};

/// The methods uploaded, with LaTeX and CSV specials in their names, and their files.
const METHODS: [(&str, &str); 3] = [
    ("Pose_Net & co. 100%", "results/noisesmall_synthA-test.csv"),
    ("Two#{x} $y", "results/noisemedium_synthA-test.csv"),
    ("three, \"quoted\"", "results/noiselarge_synthA-test.csv"),
];

/// The names as the LaTeX must print them.
fn escaped(name: &str) -> &'static str {
    match name {
        "Pose_Net & co. 100%" => r"Pose\_Net \& co. 100\%",
        "Two#{x} $y" => r"Two\#\{x\} \$y",
        "three, \"quoted\"" => "three, \"quoted\"",
        other => panic!("unexpected method {other}"),
    }
}

/// RFC 4180 records (quoted fields, doubled quotes, CRLF).
pub(crate) fn parse_csv(text: &str) -> Vec<Vec<String>> {
    let (mut records, mut record, mut field) = (Vec::new(), Vec::new(), String::new());
    let mut chars = text.chars().peekable();
    let mut quoted = false;
    while let Some(c) = chars.next() {
        match (quoted, c) {
            (true, '"') if chars.peek() == Some(&'"') => {
                chars.next();
                field.push('"');
            }
            (true, '"') => quoted = false,
            (true, c) => field.push(c),
            (false, '"') => quoted = true,
            (false, ',') => record.push(std::mem::take(&mut field)),
            (false, '\r') => {}
            (false, '\n') => {
                record.push(std::mem::take(&mut field));
                records.push(std::mem::take(&mut record));
            }
            (false, c) => field.push(c),
        }
    }
    assert!(
        field.is_empty() && record.is_empty(),
        "the CSV ends with a line break"
    );
    records
}

/// `&` cells separators of a LaTeX line (escaped `\&` excluded).
fn separators(line: &str) -> usize {
    line.match_indices('&')
        .filter(|(i, _)| !line[..*i].ends_with('\\'))
        .count()
}

/// A download: asserts the status, type and attachment name, and returns the body.
fn download(url: &str, content_type: &str, extension: &str) -> String {
    let r = client().get(url).send().expect("answered");
    assert_eq!(r.status(), 200, "{url}");
    let h = r.headers();
    let ct = h["content-type"].to_str().expect("type");
    assert!(ct.starts_with(content_type), "{url}: {ct}");
    let cd = h["content-disposition"].to_str().expect("disposition");
    assert!(
        cd.starts_with("attachment; filename=\"poseboard-bop19"),
        "{cd}"
    );
    assert!(cd.ends_with(&format!(".{extension}\"")), "{cd}");
    r.text().expect("text")
}

/// Checks the three exports of the board at `query` against its JSON rows.
fn check_exports(base: &str, query: &str, board: &Value) {
    let rows = board["rows"].as_array().expect("rows");
    let columns: Vec<&str> = board["columns"]
        .as_array()
        .expect("columns")
        .iter()
        .map(|c| c["name"].as_str().expect("name"))
        .collect();
    let export = |ext: &str, ct: &str| {
        download(
            &format!("{base}/leaderboards/bop19/export.{ext}{query}"),
            ct,
            ext,
        )
    };

    // JSON: the very rows.
    let json: Value = serde_json::from_str(&export("json", "application/json")).expect("JSON");
    assert_eq!(&json["rows"], &board["rows"], "{query}");

    // CSV: a row per board row, in order, with the same names, scores and records.
    let csv = parse_csv(&export("csv", "text/csv"));
    let header = &csv[0];
    let at = |name: &str| {
        header
            .iter()
            .position(|h| h == name)
            .unwrap_or_else(|| panic!("no column {name} in {header:?}"))
    };
    assert_eq!(csv.len(), rows.len() + 1, "{query}");
    for (line, row) in csv[1..].iter().zip(rows) {
        assert_eq!(line.len(), header.len());
        assert_eq!(line[at("method")], row["method"].as_str().expect("method"));
        for d in &columns {
            let cell = &row["scores"][d];
            let score: f64 = line[at(&format!("{d} score"))].parse().expect("score");
            assert_eq!(score, cell["score"].as_f64().expect("score"));
            let record = &cell["record"];
            for key in [
                "evaluator_version",
                "protocol",
                "dataset_hash",
                "file_sha256",
            ] {
                assert_eq!(
                    line[at(&format!("{d} {key}"))],
                    record[key].as_str().expect(key)
                );
            }
            let parameters: Value =
                serde_json::from_str(&line[at(&format!("{d} parameters"))]).expect("JSON");
            assert_eq!(parameters, record["parameters"]);
        }
        if let Some(avg) = row["average"].as_f64() {
            assert_eq!(line[at("average")].parse::<f64>().expect("average"), avg);
        }
    }

    // LaTeX: one complete tabular, every row with a cell per column, the best of each in bold.
    let tex = export("tex", "application/x-tex");
    assert_eq!(tex.matches("\\begin{tabular}").count(), 1, "{tex}");
    assert_eq!(tex.matches("\\end{tabular}").count(), 1, "{tex}");
    let begin = tex.find("\\begin{tabular}").expect("begin");
    let end = tex.find("\\end{tabular}").expect("end");
    assert!(begin < end);
    let body: Vec<&str> = tex[begin..end].lines().collect();
    let spec = body[0]
        .strip_prefix("\\begin{tabular}{")
        .and_then(|s| s.strip_suffix('}'))
        .expect("column spec");
    let ncols = spec.chars().filter(|c| c.is_ascii_alphabetic()).count();
    let (mid, bottom) = (
        body.iter()
            .position(|l| *l == "\\midrule")
            .expect("midrule"),
        body.iter()
            .position(|l| *l == "\\bottomrule")
            .expect("bottomrule"),
    );
    assert_eq!(body[1], "\\toprule");
    let heading = body[mid - 1];
    assert_eq!(separators(heading), ncols - 1, "{heading}");
    assert!(heading.ends_with("\\\\"));
    let table_rows = &body[mid + 1..bottom];
    assert_eq!(table_rows.len(), rows.len(), "{tex}");
    let mut cells: Vec<Vec<String>> = Vec::new();
    for (line, row) in table_rows.iter().zip(rows) {
        assert!(line.ends_with(" \\\\"), "{line}");
        assert_eq!(separators(line), ncols - 1, "{line}");
        let parts: Vec<String> = split_cells(line.strip_suffix(" \\\\").expect("row end"));
        assert_eq!(parts[0], escaped(row["method"].as_str().expect("method")));
        cells.push(parts);
    }
    let headings = split_cells(heading.strip_suffix(" \\\\").expect("end"));
    for j in 1..ncols {
        let value = |c: &str| {
            let plain = c
                .strip_prefix("\\textbf{")
                .and_then(|c| c.strip_suffix('}'))
                .unwrap_or(c);
            plain.parse::<f64>().ok()
        };
        let shown: Vec<Option<f64>> = cells.iter().map(|r| value(&r[j])).collect();
        let lower = headings[j].starts_with("Time");
        let best = shown
            .iter()
            .flatten()
            .copied()
            .reduce(|a, b| if lower { a.min(b) } else { a.max(b) });
        for (r, v) in cells.iter().zip(&shown) {
            let bold = r[j].starts_with("\\textbf{");
            assert_eq!(
                bold,
                v.is_some() && *v == best,
                "column {}: {:?}",
                headings[j],
                r
            );
        }
    }
    // Per the JSON, the score columns (in %) of each dataset shown.
    for (j, d) in columns.iter().enumerate() {
        let j = if query.contains("dataset=") {
            ncols - 2
        } else {
            j + 1
        };
        for (r, row) in cells.iter().zip(rows) {
            let plain = r[j].trim_start_matches("\\textbf{").trim_end_matches('}');
            match row["scores"][d]["score"].as_f64() {
                Some(s) => assert_eq!(plain, format!("{:.1}", s * 100.0)),
                None => assert_eq!(plain, "--"),
            }
        }
    }
    // The records, as comment lines after the table.
    for row in rows {
        for cell in row["scores"].as_object().expect("scores").values() {
            let r = &cell["record"];
            let line = tex[end..]
                .lines()
                .find(|l| l.contains(r["file_sha256"].as_str().expect("sha")))
                .expect("a record line");
            assert!(line.starts_with('%'));
            assert!(
                line.contains(r["dataset_hash"].as_str().expect("hash")),
                "{line}"
            );
            assert!(line.contains(r["evaluator_version"].as_str().expect("version")));
        }
    }
}

/// The cells of a LaTeX row (split at unescaped `&`).
fn split_cells(line: &str) -> Vec<String> {
    let mut cells = vec![String::new()];
    let mut prev = ' ';
    for c in line.chars() {
        if c == '&' && prev != '\\' {
            cells.push(String::new());
        } else {
            cells.last_mut().expect("cell").push(c);
        }
        prev = c;
    }
    cells.iter().map(|c| c.trim().to_string()).collect()
}

fn exports(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let db = TestDb::new(kind, "exports");
    let datasets = reference_datasets(dir.path());
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    let base = server.base.clone();
    let mut ids = BTreeMap::new();
    for (method, file) in METHODS {
        let r = upload(
            &server,
            method,
            "synthA",
            &fixtures().join(file),
            Some("bop19"),
        );
        assert_eq!(r.status(), 202, "{method}");
        let id = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
        ids.insert(method, (id, file));
    }
    for (id, _) in ids.values() {
        wait_done(&base, *id, std::time::Duration::from_secs(120));
    }

    let board = get_json(&format!("{base}/api/v1/leaderboards/bop19"));
    assert_eq!(board["rows"].as_array().expect("rows").len(), METHODS.len());
    check_exports(&base, "", &board);
    let one = get_json(&format!(
        "{base}/api/v1/leaderboards/bop19?dataset=synthA&sort=method"
    ));
    check_exports(&base, "?dataset=synthA&sort=method", &one);

    // The records hold what the store holds: the dataset's content hash as registered, the
    // hash of the bytes uploaded, the evaluator's version and the report's parameters.
    let registered = column(
        &db,
        &data,
        "SELECT content_hash FROM datasets WHERE name = 'synthA'",
    );
    assert_eq!(registered.len(), 1);
    for row in board["rows"].as_array().expect("rows") {
        let method = row["method"].as_str().expect("method");
        let (id, file) = ids[method];
        let record = &row["scores"]["synthA"]["record"];
        let bytes = std::fs::read(fixtures().join(file)).expect("file");
        assert_eq!(record["file_sha256"], hex::encode(Sha256::digest(&bytes)));
        assert_eq!(record["dataset_hash"], registered[0].as_str());
        assert_eq!(
            record["evaluator_version"],
            evaluator::report::EVALUATOR_VERSION
        );
        assert_eq!(record["protocol"], "bop19");
        let submission = get_json(&format!("{base}/api/v1/submissions/{id}"));
        // The report's parameters, as the protocol defines them.
        let used: evaluator::report::Parameters =
            serde_json::from_value(submission["scores"]["bop19"]["parameters"].clone())
                .expect("parameters");
        assert_eq!(
            record["parameters"],
            serde_json::to_value(used.as_defined()).expect("JSON")
        );
        assert_eq!(&submission["records"]["bop19"], record);
        let page = client()
            .get(format!("{base}/submissions/{id}"))
            .send()
            .expect("page")
            .text()
            .expect("html");
        assert!(
            page.contains(registered[0].as_str()),
            "dataset hash on the page"
        );
        assert!(page.contains(record["file_sha256"].as_str().expect("sha")));
    }

    // The board page links its exports, with its query.
    let page = client()
        .get(format!("{base}/leaderboards/bop19?dataset=synthA"))
        .send()
        .expect("page")
        .text()
        .expect("html");
    for ext in ["csv", "json", "tex"] {
        assert!(
            page.contains(&format!("/leaderboards/bop19/export.{ext}?dataset=synthA")),
            "{ext}"
        );
    }

    // A withdrawal shows in the exports at once.
    let (gone, _) = ids[METHODS[0].0];
    let r = client()
        .post(format!("{base}/api/v1/submissions/{gone}/visibility"))
        .bearer_auth(&server.token)
        .form(&[("visibility", "private")])
        .send()
        .expect("answered");
    assert_eq!(r.status(), 200);
    let after = get_json(&format!("{base}/api/v1/leaderboards/bop19"));
    assert_eq!(
        after["rows"].as_array().expect("rows").len(),
        METHODS.len() - 1
    );
    check_exports(&base, "", &after);

    for bad in [
        "/leaderboards/bop99/export.csv",
        "/leaderboards/bop19/export.tex?dataset=nope",
    ] {
        let r = client()
            .get(format!("{base}{bad}"))
            .send()
            .expect("answered");
        assert_eq!(r.status(), 404, "{bad}");
    }
}
both_databases!(exports);
