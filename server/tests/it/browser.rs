//! The pages in a real browser: Debian's chromium, driven over WebDriver by chromedriver, against
//! the real server. A person's path through the site (register, sign in, create a token, upload
//! through the form, watch the evaluation, find the score on the leaderboard), what a signed-out
//! visitor cannot see, and the phone layout (at 390 px no page scrolls sideways). Screenshots of
//! the main pages at desktop and phone width (a challenge's page among them, after its
//! deadline) go to `target/screenshots/` (or
//! `$POSEBOARD_SCREENSHOTS`).
//!
//! The pages do not depend on the database kind, so this runs on SQLite only.
//!
//! Needs `chromedriver` and `chromium` (Debian: `apt-get install chromium chromium-driver`;
//! `.ci/run` installs them); without them the test fails saying so.

use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::{
    BIN, Db, TestDb, admin_token, cli_report, fixtures, get_json, post_as, reference_datasets,
    start, upload, wait_done,
};
use fantoccini::{Client, ClientBuilder, Locator};
use serde_json::{Value, json};

const PHONE: u32 = 390;
const DESKTOP: u32 = 1280;
const PASSWORD: &str = "correct horse battery";

/// A program of this machine: the path in `env` if set, else the first of `names` on the PATH.
fn program(env: &str, names: &[&str]) -> Option<PathBuf> {
    if let Some(p) = std::env::var_os(env) {
        return Some(PathBuf::from(p));
    }
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .flat_map(|dir| names.iter().map(move |n| dir.join(n)))
        .find(|p| p.is_file())
}

fn missing(what: &str) -> ! {
    panic!(
        "{what} is not installed: the browser tests need Debian's chromium and chromium-driver \
         (`apt-get install chromium chromium-driver`; .ci/run installs them)"
    )
}

/// chromedriver on a free port, stopped when this goes away.
struct Driver {
    child: Child,
    url: String,
}

impl Drop for Driver {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn start_driver() -> Driver {
    let bin = program("POSEBOARD_CHROMEDRIVER", &["chromedriver"])
        .unwrap_or_else(|| missing("chromedriver"));
    let port = TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port();
    let child = Command::new(bin)
        .arg(format!("--port={port}"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("chromedriver starts");
    Driver {
        child,
        url: format!("http://127.0.0.1:{port}"),
    }
}

/// A headless chromium session (chromedriver may take a moment to listen).
async fn browser(driver: &Driver, profile: &Path) -> Client {
    let chromium = program("POSEBOARD_CHROMIUM", &["chromium", "chromium-browser"])
        .unwrap_or_else(|| missing("chromium"));
    let mut caps = serde_json::Map::new();
    caps.insert(
        "goog:chromeOptions".to_string(),
        json!({
            "binary": chromium,
            "args": [
                "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--no-first-run", "--disable-background-networking", "--disable-component-update",
                "--disable-sync", "--disable-quic", "--hide-scrollbars",
                format!("--window-size={DESKTOP},900"),
                format!("--user-data-dir={}", profile.display()),
            ],
        }),
    );
    let start = Instant::now();
    loop {
        let connector = hyper_util::client::legacy::connect::HttpConnector::new();
        match ClientBuilder::new(connector)
            .capabilities(caps.clone())
            .connect(&driver.url)
            .await
        {
            Ok(c) => return c,
            Err(_) if start.elapsed() < Duration::from_secs(15) => {
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
            Err(e) => panic!("no chromium session from chromedriver: {e}"),
        }
    }
}

/// Where screenshots go: `$POSEBOARD_SCREENSHOTS`, else the workspace's `target/screenshots`.
fn screenshot_dir() -> PathBuf {
    let dir = std::env::var_os("POSEBOARD_SCREENSHOTS").map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/screenshots"),
        PathBuf::from,
    );
    std::fs::create_dir_all(&dir).expect("screenshot folder");
    dir
}

/// The element `selector` finds, waiting up to 10 s for it (a page may still be loading after
/// a form was submitted).
async fn css(c: &Client, selector: &str) -> fantoccini::elements::Element {
    let found = c
        .wait()
        .at_most(Duration::from_secs(10))
        .for_element(Locator::Css(selector))
        .await;
    match found {
        Ok(el) => el,
        Err(e) => panic!("`{selector}` on {:?}: {e}", c.current_url().await),
    }
}

async fn text(c: &Client, selector: &str) -> String {
    css(c, selector).await.text().await.expect("text")
}

async fn script(c: &Client, js: &str) -> Value {
    c.execute(js, Vec::new()).await.expect("script runs")
}

/// Sets the window so that the page is `width` CSS pixels wide.
async fn page_width(c: &Client, width: u32) {
    c.set_window_size(width, 900).await.expect("resize");
    let inner = script(c, "return window.innerWidth").await;
    let inner = inner.as_u64().expect("innerWidth") as u32;
    if inner != width {
        // A window frame: make the inside, not the outside, that wide.
        c.set_window_size(2 * width - inner, 900)
            .await
            .expect("resize");
    }
    let inner = script(c, "return window.innerWidth").await;
    assert_eq!(inner.as_u64(), Some(u64::from(width)), "page width");
}

async fn fill(c: &Client, form: &str, fields: &[(&str, &str)]) {
    for (name, value) in fields {
        let input = css(c, &format!("{form} [name=\"{name}\"]")).await;
        input.clear().await.expect("clear");
        input.send_keys(value).await.expect("type");
    }
}

/// Submits `form` and waits until the browser has left the page (the old page's root element
/// goes stale), so that what is read next is the answer's page.
async fn submit(c: &Client, form: &str) {
    let old_page = css(c, "html").await;
    press(c, form).await;
    let start = Instant::now();
    while old_page.tag_name().await.is_ok() {
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "`{form}` did not lead to a new page"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// Clicks `form`'s submit button (for a form that asks first: the page stays).
async fn press(c: &Client, form: &str) {
    css(c, &format!("{form} button[type=\"submit\"]"))
        .await
        .click()
        .await
        .expect("submit");
}

/// Uploads `file` through the submit form, with "publish when evaluated" ticked or not, and
/// returns the submission's id, from the page the form leads to.
async fn upload_form(c: &Client, base: &str, method: &str, file: &Path, publish: bool) -> i64 {
    c.goto(&format!("{base}/submit"))
        .await
        .expect("submit page");
    fill(c, "form.submit", &[("method", method)]).await;
    let select = |name: &'static str| async move {
        css(c, &format!("form.submit select[name=\"{name}\"]")).await
    };
    select("dataset")
        .await
        .select_by_value("synthA")
        .await
        .expect("dataset");
    select("protocol")
        .await
        .select_by_value("bop19")
        .await
        .expect("protocol");
    // Its categories, so that a filtered board has rows to show.
    select("objects")
        .await
        .select_by_value("unseen")
        .await
        .expect("objects");
    select("onboarding")
        .await
        .select_by_value("model-based")
        .await
        .expect("onboarding");
    let publish_box = css(c, "form.submit input[name=\"publish\"]").await;
    let ticked = publish_box.prop("checked").await.expect("checked?");
    assert_eq!(
        ticked.as_deref(),
        Some("true"),
        "publishing is the form's default"
    );
    if !publish {
        publish_box.click().await.expect("untick publish");
    }
    css(c, "form.submit input[type=\"file\"]")
        .await
        // WebDriver takes only canonical paths.
        .send_keys(
            file.canonicalize()
                .expect("the result file")
                .to_str()
                .expect("path"),
        )
        .await
        .expect("file chosen");
    submit(c, "form.submit").await;
    c.wait()
        .at_most(Duration::from_secs(20))
        .for_element(Locator::Css("#status"))
        .await
        .expect("the submission's page");
    let id = css(c, "#status").await.attr("data-id").await.expect("attr");
    id.and_then(|v| v.parse().ok())
        .expect("the submission's id")
}

/// Waits until the page's status reads `done`, returning every status seen on the way.
async fn watch_until_done(c: &Client) -> Vec<String> {
    let mut seen: Vec<String> = Vec::new();
    let start = Instant::now();
    loop {
        // The page reloads itself when the job ends: the element may be replaced under us.
        if let Ok(el) = c.find(Locator::Css("#status-text")).await
            && let Ok(t) = el.text().await
        {
            if seen.last() != Some(&t) {
                seen.push(t.clone());
            }
            if t.starts_with("done") {
                return seen;
            }
            assert!(!t.starts_with("failed"), "the evaluation failed: {seen:?}");
        }
        assert!(
            start.elapsed() < Duration::from_secs(40),
            "not done in time: {seen:?}"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// `poseboard worker` on the server's database: the jobs queued so far get evaluated.
fn start_worker(data: &Path, datasets: &Path) -> Child {
    Command::new(BIN)
        .arg("worker")
        .arg("--data-dir")
        .arg(data.join("worker"))
        .arg("--datasets")
        .arg(datasets)
        .env(
            "DATABASE_URL",
            format!("sqlite://{}", data.join("poseboard.db").display()),
        )
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("worker starts")
}

struct Worker(Child);

impl Drop for Worker {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The menu of the current page (at desktop width, where it is not folded) offers a signed-in
/// browser its submissions and account, and anyone else Sign in and Register.
async fn menu_follows_sign_in(c: &Client, signed_in: bool) {
    for (href, for_signed_in) in [
        ("/me/submissions", true),
        ("/account", true),
        ("/login", false),
        ("/register", false),
    ] {
        let link = css(c, &format!("header nav a[href=\"{href}\"]")).await;
        let shown = link.is_displayed().await.expect("shown?");
        assert_eq!(
            shown,
            for_signed_in == signed_in,
            "the menu's {href} link, signed {}",
            if signed_in { "in" } else { "out" }
        );
    }
}

/// The dataset as wide as T-LESS: 30 objects (copies of the synthetic shapes), in one scene of
/// small images so that it is quick to make and to score.
const WIDE: &str = "synth30";

/// Writes [`WIDE`] into `datasets`, and demo result files for it into `dir`: a 6D file (for
/// bop19 and for bop24) and the 2D detector's and segmenter's, each with the task it is for.
fn wide_dataset(datasets: &Path, dir: &Path) -> Vec<(PathBuf, &'static str)> {
    let dataset = datasets.join(WIDE);
    let run = |args: &[&str], paths: &[&Path]| {
        let out = Command::new(BIN)
            .args(args)
            .args(paths)
            .output()
            .expect("poseboard runs");
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    let synth = [
        "dataset",
        "synth",
        "--objects",
        "30",
        "--scenes",
        "1",
        "--images-per-scene",
        "16",
        "--size",
        "320x240",
    ];
    run(&synth, &[&dataset]);
    let (poses, coco) = (dir.join("wide-6d"), dir.join("wide-2d"));
    run(&["dataset", "demo-results"], &[&dataset, &poses]);
    run(&["dataset", "demo-results", "--coco"], &[&dataset, &coco]);
    let named = |folder: &Path, file: &str| folder.join(format!("{file}_{WIDE}-test"));
    vec![
        // One 6D file is enough for a board with a column per object; the same file scored
        // for 6D detection fills the bop24 board's (the dataset has its BOP'24 targets).
        (named(&poses, "demo-precise").with_extension("csv"), "bop19"),
        (named(&poses, "demo-precise").with_extension("csv"), "bop24"),
        (
            named(&coco, "demo-detector").with_extension("json"),
            "bop22-det",
        ),
        (
            named(&coco, "demo-segmenter").with_extension("json"),
            "bop22-seg",
        ),
    ]
}

/// Every board: each protocol over all core datasets and on each dataset, the wide one too.
fn every_board(base: &str) -> Vec<String> {
    let mut boards = Vec::new();
    for protocol in ["bop19", "eccv18", "bop24", "bop22-det", "bop22-seg"] {
        boards.push(format!("{base}/leaderboards/{protocol}"));
        for dataset in ["synthA", WIDE] {
            boards.push(format!("{base}/leaderboards/{protocol}?dataset={dataset}"));
        }
    }
    boards
}

/// Asserts that the page at `url` does not scroll sideways at the window's width.
async fn fits_the_width(c: &Client, url: &str) {
    let widths = script(
        c,
        "return [document.scrollingElement.scrollWidth, window.innerWidth]",
    )
    .await;
    let (scroll, inner) = (widths[0].as_u64(), widths[1].as_u64());
    assert!(
        scroll <= inner,
        "{url} scrolls sideways: {scroll:?} px wide at {inner:?} px"
    );
}

/// On the board at `url` (one with rows), the score is the column right after the method, so
/// that a phone shows the two together.
async fn score_follows_method(c: &Client, url: &str) {
    let next = script(
        c,
        "var m = document.querySelector('table.board thead th.sticky'); \
         return m ? m.nextElementSibling.className : null;",
    )
    .await;
    if let Some(class) = next.as_str() {
        assert!(
            class.split(' ').any(|k| k == "score"),
            "{url}: the column after the method is `{class}`, not the score"
        );
    }
}

/// The wide board at the window's width: its 30 object columns scroll in the table's own box,
/// and scrolled to the far right the method column is still in view at the box's left edge.
async fn wide_board_scrolls_in_its_box(c: &Client, base: &str) {
    let url = format!("{base}/leaderboards/bop19?dataset={WIDE}");
    c.goto(&url).await.expect("the wide board");
    let objects = script(
        c,
        "return document.querySelectorAll('table.board th.obj').length",
    )
    .await;
    assert_eq!(objects.as_u64(), Some(30), "a column per object on {url}");
    fits_the_width(c, &url).await;
    let scrolled = script(
        c,
        "var t = document.querySelector('table.board'); \
         var wide = t.scrollWidth > t.clientWidth; \
         t.scrollLeft = t.scrollWidth; \
         var cell = t.querySelector('tbody td.sticky').getBoundingClientRect(); \
         var box = t.getBoundingClientRect(); \
         return [wide, t.scrollLeft > 0, cell.left - box.left, cell.right <= box.right];",
    )
    .await;
    assert_eq!(
        scrolled[0],
        json!(true),
        "the table is wider than its box: {scrolled}"
    );
    assert_eq!(
        scrolled[1],
        json!(true),
        "the table's box scrolls: {scrolled}"
    );
    let offset = scrolled[2].as_f64().expect("offset");
    assert!(
        offset.abs() < 1.0 && scrolled[3] == json!(true),
        "scrolled right, the method column stays at the box's left edge: {scrolled}"
    );
}

/// The charts of the page at `url`, at the window's width: axis labels at least 11 px as drawn,
/// and within a chart no two curves drawn alike (each its own dash pattern).
async fn charts_are_legible(c: &Client, url: &str) {
    c.goto(url).await.expect("page");
    let found = script(
        c,
        "var out = []; \
         document.querySelectorAll('.charts svg').forEach(function (svg) { \
           var scale = svg.getBoundingClientRect().width / svg.viewBox.baseVal.width; \
           var sizes = []; \
           svg.querySelectorAll('text.tick, text.axis').forEach(function (t) { \
             sizes.push(parseFloat(getComputedStyle(t).fontSize) * scale); }); \
           var dashes = []; \
           svg.querySelectorAll('polyline.line').forEach(function (l) { \
             dashes.push(getComputedStyle(l).strokeDasharray); }); \
           out.push([Math.min.apply(null, sizes), dashes]); }); \
         return out;",
    )
    .await;
    let charts = found.as_array().expect("charts");
    assert!(!charts.is_empty(), "charts on {url}");
    for chart in charts {
        let smallest = chart[0].as_f64().expect("a size");
        assert!(smallest >= 11.0, "axis labels of {smallest:.1} px on {url}");
        let dashes: Vec<&str> = chart[1]
            .as_array()
            .expect("dashes")
            .iter()
            .map(|d| d.as_str().expect("dash"))
            .collect();
        let distinct: std::collections::BTreeSet<&&str> = dashes.iter().collect();
        assert_eq!(
            distinct.len(),
            dashes.len(),
            "curves drawn alike on {url}: {dashes:?}"
        );
    }
}

/// Creates the challenge `bop-browser` over a group of `synthA` (its deadline two seconds
/// ahead) and waits until the server has taken its snapshot.
fn challenge_past_its_deadline(base: &str, admin: &str) {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .expect("clock")
        .as_secs()
        + 2;
    let (days, rem) = (now / 86_400, now % 86_400);
    // The date of `days` since 1970 (H. Hinnant's civil_from_days, for dates after 2000).
    let z = days as i64 + 719_468;
    let (era, doe) = (z / 146_097, z % 146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    let deadline = format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    );
    // Over the one dataset the browser's entry covers (the wide one is core too).
    let r = post_as(
        &format!("{base}/api/v1/admin/groups"),
        admin,
        Some(json!({ "name": "synth-a", "datasets": ["synthA"] })),
    );
    assert!(r.status().is_success(), "{}", r.text().unwrap_or_default());
    let r = post_as(
        &format!("{base}/api/v1/admin/challenges"),
        admin,
        Some(
            json!({ "slug": "bop-browser", "name": "BOP browser challenge", "tasks": ["bop19", "eccv18"], "groups": ["synth-a"], "deadline": deadline }),
        ),
    );
    assert_eq!(r.status(), 201, "{}", r.text().unwrap_or_default());
    let start = Instant::now();
    while !get_json(&format!("{base}/api/v1/challenges/bop-browser"))["snapshot_id"].is_i64() {
        assert!(start.elapsed() < Duration::from_secs(60), "no snapshot");
        std::thread::sleep(Duration::from_millis(200));
    }
}

#[test]
fn pages_work_in_a_real_browser() {
    let driver = start_driver();
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let wide_files = wide_dataset(&datasets, dir.path());
    let data = dir.path().join("data");
    let db = TestDb::new(Db::Sqlite, "browser");
    // No worker in the server: the test starts one once it has seen its upload wait in the queue.
    // Deadlines looked at every second: the challenge's page is seen with its awards decided.
    let server = start(
        &data,
        &datasets,
        &db,
        &["--no-demo", "--workers", "0", "--challenge-check-secs", "1"],
    );
    // Public scored submissions on the wide dataset, 6D and 2D (queued now, scored by that
    // worker), so that its boards have their widest tables: a column per object, the 2D stats.
    let wide_ids: Vec<i64> = wide_files
        .iter()
        .map(|(file, task)| {
            let r = upload(&server, &format!("wide-{task}"), WIDE, file, Some(task));
            assert!(r.status().is_success(), "{task}: {}", r.status());
            r.json::<Value>().expect("JSON")["id"]
                .as_i64()
                .expect("the wide submission's id")
        })
        .collect();
    let public_file = fixtures().join("results/noisemedium_synthA-test.csv");
    let private_file = fixtures().join("results/noisesmall_synthA-test.csv");
    let expected = cli_report(&fixtures().join("dataset"), &public_file, "bop19");
    let expected_ar = expected["bop19_average_recall"]
        .as_f64()
        .expect("AR from poseboard eval");
    let profile = dir.path().join("chromium-profile");

    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    rt.block_on(async {
        let c = browser(&driver, &profile).await;
        let base = server.base.as_str();
        let shots = screenshot_dir();

        // Register, sign out, sign in again.
        c.goto(&format!("{base}/register"))
            .await
            .expect("register page");
        fill(
            &c,
            "form.submit",
            &[("name", "alice"), ("password", PASSWORD)],
        )
        .await;
        submit(&c, "form.submit").await;
        assert_eq!(
            text(&c, "h1").await,
            "alice",
            "the account page after registering"
        );
        submit(&c, "form[action=\"/logout\"]").await;
        c.goto(&format!("{base}/login")).await.expect("login page");
        fill(
            &c,
            "form.submit",
            &[("name", "alice"), ("password", PASSWORD)],
        )
        .await;
        submit(&c, "form.submit").await;
        assert_eq!(
            text(&c, "h1").await,
            "alice",
            "the account page after signing in"
        );
        menu_follows_sign_in(&c, true).await;

        // A token: shown once in its box, with a copy button and a curl example for this server.
        fill(
            &c,
            "form[action=\"/account/tokens\"]",
            &[("name", "laptop")],
        )
        .await;
        submit(&c, "form[action=\"/account/tokens\"]").await;
        let token = text(&c, "#token-box #new-token").await;
        assert!(token.len() >= 32, "a token: {token:?}");
        let example = text(&c, "#token-box #curl-example").await;
        assert!(
            example.contains(&format!("Bearer {token}"))
                && example.contains(&format!("{base}/api/v1/submissions")),
            "{example}"
        );
        let copy = css(&c, "#token-box button[data-copy=\"new-token\"]").await;
        copy.click().await.expect("copy");
        // The button answers at once (its script runs under the CSP), then says what the
        // clipboard did; it reads "Copy" again two seconds later.
        let label = copy.text().await.expect("label");
        assert!(
            ["Copying…", "Copied", "Selected: press Ctrl+C"].contains(&label.as_str()),
            "the copy button answers (its script runs under the CSP): {label:?}"
        );
        // Revoking asks first; saying no keeps the token.
        press(&c, "form[action$=\"/revoke\"]").await;
        let question = c.get_alert_text().await.expect("a confirmation");
        assert!(
            question.starts_with("Revoke the token laptop"),
            "{question}"
        );
        c.dismiss_alert().await.expect("dismissed");
        c.goto(&format!("{base}/account")).await.expect("account");
        assert!(
            c.find(Locator::Css("form[action$=\"/revoke\"]"))
                .await
                .is_ok(),
            "the token is still there"
        );

        // Upload through the form, kept private for now, and watch it go from the queue to done.
        let id = upload_form(&c, base, "browser-net", &public_file, false).await;
        let status = text(&c, "#status-text").await;
        assert!(
            status.starts_with("queued"),
            "before a worker runs: {status}"
        );
        let _worker = Worker(start_worker(&data, &datasets));
        let seen = watch_until_done(&c).await;
        assert!(seen.len() >= 2, "the page followed the job: {seen:?}");
        let submission_url = format!("{base}/submissions/{id}");
        let method_href = css(&c, "h1 a[href^=\"/methods/\"]")
            .await
            .attr("href")
            .await
            .expect("attr")
            .expect("the method's link");

        // Not on the board until published; then the board shows the score `poseboard eval`
        // gives for the file.
        let board = format!("{base}/leaderboards/bop19?dataset=synthA");
        c.goto(&board).await.expect("leaderboard");
        assert!(
            c.find(Locator::Css(&format!("a[href=\"/submissions/{id}\"]")))
                .await
                .is_err(),
            "a private submission is on the board"
        );
        c.goto(&submission_url).await.expect("submission page");
        submit(
            &c,
            &format!("form[action=\"/submissions/{id}/visibility\"]"),
        )
        .await;
        assert_eq!(
            text(&c, "#publication").await,
            "public",
            "published from its page"
        );
        c.goto(&board).await.expect("leaderboard");
        let score = text(&c, &format!("a[href=\"/submissions/{id}\"]")).await;
        assert_eq!(
            score,
            format!("{:.1}", expected_ar * 100.0),
            "the board's score"
        );

        // A challenge over the published entry, its deadline two seconds ahead: its page is
        // seen (below) once the snapshot is taken and the awards decided.
        let boss = admin_token(&data, &db, "boss");
        let (base_owned, boss_owned) = (base.to_string(), boss.clone());
        tokio::task::spawn_blocking(move || challenge_past_its_deadline(&base_owned, &boss_owned))
            .await
            .expect("the challenge's snapshot is taken");

        // A private upload: its owner sees it, a signed-out visitor finds it nowhere.
        let hidden = upload_form(&c, base, "hidden-net", &private_file, false).await;
        watch_until_done(&c).await;
        let hidden_method = css(&c, "h1 a[href^=\"/methods/\"]")
            .await
            .attr("href")
            .await
            .expect("attr")
            .expect("link");
        c.goto(&format!("{base}/account")).await.expect("account");
        submit(&c, "form[action=\"/logout\"]").await;
        for url in [board.clone(), format!("{base}/")] {
            c.goto(&url).await.expect("board");
            menu_follows_sign_in(&c, false).await;
            let page = c.source().await.expect("html");
            assert!(page.contains("browser-net"), "{url}: the public entry");
            assert!(
                !page.contains("hidden-net"),
                "{url}: the private one is listed"
            );
        }
        for url in [
            format!("{base}/submissions/{hidden}"),
            format!("{base}{hidden_method}"),
        ] {
            c.goto(&url).await.expect("page");
            assert_eq!(text(&c, "h1").await, "Not found", "{url} signed out");
        }

        // The API page lists every route of the OpenAPI document.
        c.goto(&format!("{base}/docs/api")).await.expect("API page");
        let api_page = text(&c, "main").await;
        let doc = script(
            &c,
            "return fetch('/api/v1/openapi.json').then(function (r) { return r.json(); })",
        )
        .await;
        for path in doc["paths"].as_object().expect("paths").keys() {
            assert!(api_page.contains(path.as_str()), "{path} on /docs/api");
        }

        // Signed in again for the account and submit pages.
        c.goto(&format!("{base}/login")).await.expect("login page");
        fill(
            &c,
            "form.submit",
            &[("name", "alice"), ("password", PASSWORD)],
        )
        .await;
        submit(&c, "form.submit").await;

        let pages = [
            ("home", format!("{base}/")),
            ("leaderboard", board.clone()),
            ("datasets", format!("{base}/datasets")),
            ("method", format!("{base}{method_href}")),
            ("submission", submission_url.clone()),
            ("account", format!("{base}/account")),
            ("submit", format!("{base}/submit")),
            ("api", format!("{base}/docs/api")),
            ("recent", format!("{base}/submissions")),
            (
                "filtered-board",
                format!("{base}/leaderboards/bop19?objects=unseen&onboarding=model-based"),
            ),
            ("groups", format!("{base}/groups")),
            ("challenge", format!("{base}/challenges/bop-browser")),
        ];
        for (width, kind) in [(DESKTOP, "desktop"), (PHONE, "phone")] {
            page_width(&c, width).await;
            for (name, url) in &pages {
                c.goto(url).await.expect("page");
                let png = c.screenshot().await.expect("screenshot");
                std::fs::write(shots.join(format!("{name}-{kind}.png")), png).expect("png");
                if width == PHONE {
                    let widths = script(
                        &c,
                        "return [document.scrollingElement.scrollWidth, window.innerWidth]",
                    )
                    .await;
                    let (scroll, inner) = (widths[0].as_u64(), widths[1].as_u64());
                    assert!(
                        scroll <= inner,
                        "{name} scrolls sideways at {PHONE} px: {scroll:?} > {inner:?}"
                    );
                }
            }
        }

        // Every board, the wide one too, fits the page at both widths; a wide table scrolls in
        // its own box with the method column in view.
        let base_owned = base.to_string();
        tokio::task::spawn_blocking(move || {
            for id in wide_ids {
                wait_done(&base_owned, id, Duration::from_secs(60));
            }
        })
        .await
        .expect("the wide submissions are scored");
        for width in [DESKTOP, PHONE] {
            page_width(&c, width).await;
            for url in every_board(base) {
                c.goto(&url).await.expect("board");
                fits_the_width(&c, &url).await;
                score_follows_method(&c, &url).await;
            }
            wide_board_scrolls_in_its_box(&c, base).await;
            let png = c.screenshot().await.expect("screenshot");
            let kind = if width == PHONE { "phone" } else { "desktop" };
            std::fs::write(shots.join(format!("wide-board-{kind}.png")), png).expect("png");
            charts_are_legible(&c, &submission_url).await;
        }

        // On a phone the menu folds away behind its button, and the board's method column
        // stays in view.
        c.goto(&board).await.expect("leaderboard");
        let nav = css(&c, "header nav").await;
        assert!(
            !nav.is_displayed().await.expect("shown?"),
            "the menu is folded"
        );
        css(&c, "label.nav-button")
            .await
            .click()
            .await
            .expect("menu");
        assert!(nav.is_displayed().await.expect("shown?"), "the menu opens");
        let sticky = css(&c, "table.board td.sticky").await;
        assert_eq!(sticky.css_value("position").await.expect("css"), "sticky");

        // The login page is seen signed out.
        c.goto(&format!("{base}/account")).await.expect("account");
        submit(&c, "form[action=\"/logout\"]").await;
        for (width, kind) in [(DESKTOP, "desktop"), (PHONE, "phone")] {
            page_width(&c, width).await;
            c.goto(&format!("{base}/login")).await.expect("login");
            let png = c.screenshot().await.expect("screenshot");
            std::fs::write(shots.join(format!("login-{kind}.png")), png).expect("png");
            let widths = script(
                &c,
                "return [document.scrollingElement.scrollWidth, window.innerWidth]",
            )
            .await;
            assert!(widths[0].as_u64() <= widths[1].as_u64(), "login: {widths}");
        }
        c.close().await.expect("session closed");
    });
}
