//! End to end: report.html in headless Chromium, driven over the Chrome
//! DevTools Protocol. The test presses the Play button with real mouse events,
//! then checks from the page that the replay advanced and drew (its own frame
//! counter and time, and canvas screenshots that are not blank and change), and
//! that the page logged no console errors or exceptions.
//!
//! Needs Debian's `chromium` (`/usr/bin/chromium`, or the path in
//! `ECHELON_CHROMIUM`); `scripts/test` installs it. Without it each test fails
//! at once and says how to install it.
#![allow(clippy::unwrap_used)]

mod common;

use std::io::{BufRead, BufReader, Read};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use base64::Engine as _;
use serde_json::{Value, json};
use tungstenite::stream::MaybeTlsStream;
use tungstenite::{Message, WebSocket};

fn chromium() -> PathBuf {
    let path = std::env::var_os("ECHELON_CHROMIUM")
        .map_or_else(|| PathBuf::from("/usr/bin/chromium"), PathBuf::from);
    assert!(
        path.exists(),
        "Chromium not found at {}: run `scripts/test`, which installs Debian's \
         `chromium`, or `apt-get install -y chromium`, or set ECHELON_CHROMIUM \
         to a Chromium binary",
        path.display()
    );
    path
}

/// A headless Chromium we started, killed on drop.
struct Browser {
    child: Child,
    _profile: tempfile::TempDir,
    ws: WebSocket<MaybeTlsStream<TcpStream>>,
    next_id: u64,
    events: Vec<Value>,
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Browser {
    fn launch() -> Browser {
        let profile = tempfile::tempdir().unwrap();
        let mut child = Command::new(chromium())
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--remote-debugging-port=0",
                "--window-size=1280,1000",
            ])
            .arg(format!("--user-data-dir={}", profile.path().display()))
            .arg("about:blank")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // Chromium prints "DevTools listening on ws://127.0.0.1:PORT/devtools/browser/ID".
        let stderr = child.stderr.take().unwrap();
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let mut reader = BufReader::new(stderr);
            let mut line = String::new();
            let mut sent = false;
            while reader.read_line(&mut line).unwrap_or(0) > 0 {
                if !sent && let Some(i) = line.find("ws://") {
                    let _ = tx.send(line[i..].trim().to_owned());
                    sent = true;
                }
                line.clear();
            }
            // Keep draining so Chromium never blocks on a full pipe.
            let _ = reader.read_to_end(&mut Vec::new());
        });
        let url = match rx.recv_timeout(Duration::from_secs(30)) {
            Ok(url) => url,
            Err(_) => {
                let _ = child.kill();
                panic!("Chromium did not print its DevTools address within 30 s");
            }
        };
        let (ws, _) = tungstenite::connect(url.as_str()).unwrap();
        if let MaybeTlsStream::Plain(s) = ws.get_ref() {
            s.set_read_timeout(Some(Duration::from_millis(200)))
                .unwrap();
        }
        Browser {
            child,
            _profile: profile,
            ws,
            next_id: 0,
            events: Vec::new(),
        }
    }

    /// Reads one message if one arrives within the read timeout.
    fn read(&mut self) -> Option<Value> {
        match self.ws.read() {
            Ok(Message::Text(t)) => Some(serde_json::from_str(t.as_str()).unwrap()),
            Ok(_) => None,
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                None
            }
            Err(e) => panic!("DevTools connection: {e}"),
        }
    }

    /// Sends a command (to a page session if given) and waits for its result;
    /// events that arrive meanwhile are kept.
    fn call(&mut self, session: Option<&str>, method: &str, params: Value) -> Value {
        self.next_id += 1;
        let id = self.next_id;
        let mut msg = json!({ "id": id, "method": method, "params": params });
        if let Some(s) = session {
            msg["sessionId"] = json!(s);
        }
        self.ws.send(Message::text(msg.to_string())).unwrap();
        let deadline = Instant::now() + Duration::from_secs(30);
        while Instant::now() < deadline {
            if let Some(v) = self.read() {
                if v["id"] == json!(id) {
                    assert!(v.get("error").is_none(), "{method}: {v}");
                    return v["result"].clone();
                }
                if v.get("method").is_some() {
                    self.events.push(v);
                }
            }
        }
        panic!("{method}: no answer within 30 s");
    }

    /// Collects events for `d`.
    fn pump(&mut self, d: Duration) {
        let end = Instant::now() + d;
        while Instant::now() < end {
            if let Some(v) = self.read()
                && v.get("method").is_some()
            {
                self.events.push(v);
            }
        }
    }

    /// Evaluates `expr` in the page and returns its value.
    fn eval(&mut self, session: &str, expr: &str) -> Value {
        let r = self.call(
            Some(session),
            "Runtime.evaluate",
            json!({ "expression": expr, "returnByValue": true, "awaitPromise": true }),
        );
        assert!(r.get("exceptionDetails").is_none(), "{expr}: {r}");
        r["result"]["value"].clone()
    }

    /// Console errors, uncaught exceptions and error log entries seen so far.
    fn errors(&self) -> Vec<String> {
        self.events
            .iter()
            .filter(|e| {
                let m = e["method"].as_str().unwrap_or("");
                m == "Runtime.exceptionThrown"
                    || (m == "Runtime.consoleAPICalled" && e["params"]["type"] == "error")
                    || (m == "Log.entryAdded" && e["params"]["entry"]["level"] == "error")
            })
            .map(Value::to_string)
            .collect()
    }
}

/// Opens `report`, returns the browser and the page's session id once the
/// replay has initialised.
fn open(report: &Path) -> (Browser, String) {
    let mut b = Browser::launch();
    let target = b.call(None, "Target.createTarget", json!({ "url": "about:blank" }));
    let target_id = target["targetId"].as_str().unwrap().to_owned();
    let attached = b.call(
        None,
        "Target.attachToTarget",
        json!({ "targetId": target_id, "flatten": true }),
    );
    let session = attached["sessionId"].as_str().unwrap().to_owned();
    for domain in ["Runtime.enable", "Log.enable", "Page.enable"] {
        b.call(Some(&session), domain, json!({}));
    }
    let url = format!("file://{}", report.canonicalize().unwrap().display());
    b.call(Some(&session), "Page.navigate", json!({ "url": url }));
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let ready = b.eval(
            &session,
            "document.readyState === 'complete' && !!window.echelonReplay && window.echelonReplay.framesDrawn > 0",
        );
        if ready == json!(true) {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "the replay did not start within 30 s; errors: {:?}",
            b.errors()
        );
        b.pump(Duration::from_millis(100));
    }
    (b, session)
}

/// Clicks the centre of the element `id` with real mouse events.
fn click(b: &mut Browser, session: &str, id: &str) {
    let rect = b.eval(
        session,
        &format!(
            "(() => {{ const e = document.getElementById('{id}'); e.scrollIntoView({{block: 'center'}}); \
             const r = e.getBoundingClientRect(); return {{x: r.x + r.width / 2, y: r.y + r.height / 2}}; }})()"
        ),
    );
    for kind in ["mouseMoved", "mousePressed", "mouseReleased"] {
        b.call(
            Some(session),
            "Input.dispatchMouseEvent",
            json!({ "type": kind, "x": rect["x"], "y": rect["y"], "button": "left", "clickCount": 1 }),
        );
    }
}

/// A PNG screenshot of the canvas: its pixels' distinct colours and its bytes.
fn canvas_shot(b: &mut Browser, session: &str) -> (usize, Vec<u8>) {
    let r = b.eval(
        session,
        "(() => { const r = document.getElementById('view').getBoundingClientRect(); \
         return {x: r.x + window.scrollX, y: r.y + window.scrollY, width: r.width, height: r.height}; })()",
    );
    let shot = b.call(
        Some(session),
        "Page.captureScreenshot",
        json!({ "format": "png", "captureBeyondViewport": true,
                "clip": { "x": r["x"], "y": r["y"], "width": r["width"], "height": r["height"], "scale": 1 } }),
    );
    let png = base64::engine::general_purpose::STANDARD
        .decode(shot["data"].as_str().unwrap())
        .unwrap();
    let mut reader = png::Decoder::new(std::io::Cursor::new(&png))
        .read_info()
        .unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    let mut colours: Vec<&[u8]> = buf[..info.buffer_size()]
        .chunks(info.color_type.samples())
        .collect();
    colours.sort_unstable();
    colours.dedup();
    (colours.len(), buf[..info.buffer_size()].to_vec())
}

/// Presses play, lets the replay run, checks it advanced and drew; returns the
/// frames drawn per second of wall time while playing and the mean time the
/// page spent drawing one frame, ms (measured, not asserted).
fn play_and_check(report: &Path) -> (f64, f64) {
    let (mut b, session) = open(report);
    let before = b.eval(&session, "window.echelonReplay");
    assert_eq!(before["playing"], json!(false));
    let (colours0, pixels0) = canvas_shot(&mut b, &session);
    // The first frame shows the reference, robots and labels: not a blank canvas.
    assert!(colours0 > 8, "the canvas looks blank: {colours0} colours");
    // Speed up, then press Play with the mouse.
    b.eval(
        &session,
        "(() => { const s = document.getElementById('speed'); s.value = '5'; s.dispatchEvent(new Event('change')); return true; })()",
    );
    click(&mut b, &session, "play");
    let started = Instant::now();
    let f0 = b
        .eval(&session, "window.echelonReplay.framesDrawn")
        .as_f64()
        .unwrap();
    b.pump(Duration::from_millis(1500));
    let after = b.eval(&session, "window.echelonReplay");
    let wall = started.elapsed().as_secs_f64();
    assert_eq!(
        after["playing"],
        json!(true),
        "Play did not start the replay: {after}"
    );
    assert!(
        after["time"].as_f64().unwrap() > before["time"].as_f64().unwrap() + 1.0,
        "the replay's time did not advance: {before} → {after}"
    );
    let frames = after["framesDrawn"].as_f64().unwrap() - f0;
    assert!(frames >= 5.0, "only {frames} frames drawn while playing");
    // The page's visible frame counter is the same counter (read in one go).
    let shown = b.eval(
        &session,
        "[window.echelonReplay.framesDrawn, document.getElementById('frames').textContent]",
    );
    assert_eq!(
        shown[0].as_f64().unwrap().to_string(),
        shown[1].as_str().unwrap()
    );
    let (colours1, pixels1) = canvas_shot(&mut b, &session);
    assert!(colours1 > 8, "the canvas looks blank while playing");
    assert!(
        pixels1 != pixels0,
        "the canvas did not change while playing"
    );
    // Press again: paused.
    click(&mut b, &session, "play");
    b.pump(Duration::from_millis(200));
    assert_eq!(
        b.eval(&session, "window.echelonReplay.playing"),
        json!(false)
    );
    let page_errors = b.eval(&session, "window.echelonReplay.errors");
    assert_eq!(page_errors, json!([]), "errors in the page");
    let errors = b.errors();
    assert!(errors.is_empty(), "console errors: {errors:?}");
    let state = b.eval(&session, "window.echelonReplay");
    let per_frame = state["drawMs"].as_f64().unwrap() / state["framesDrawn"].as_f64().unwrap();
    (frames / wall, per_frame)
}

#[test]
fn replay_plays_in_headless_chromium() {
    chromium();
    let dir = tempfile::tempdir().unwrap();
    // A 4-agent run of 70 s logged at 100 Hz.
    common::run_builtin("circle-pentagon", dir.path(), &common::for_seconds(70.0));
    echelon_report::write_all(dir.path()).unwrap();
    let (fps, ms) = play_and_check(&dir.path().join("report.html"));
    eprintln!(
        "4 agents, 70 s at 100 Hz: {fps:.0} frames per second, {ms:.2} ms to draw one (headless)"
    );
}

#[test]
fn replay_of_two_hundred_agents_plays_in_headless_chromium() {
    chromium();
    let dir = tempfile::tempdir().unwrap();
    common::run_source(
        &common::many_agents(200),
        dir.path(),
        &common::for_seconds(15.0),
    );
    echelon_report::write_all(dir.path()).unwrap();
    let (fps, ms) = play_and_check(&dir.path().join("report.html"));
    eprintln!("200 agents: {fps:.0} frames per second, {ms:.2} ms to draw one (headless)");
}

/// Measures an existing report: `ECHELON_REPORT=DIR/report.html cargo test -p
/// echelon-report --test browser -- --ignored --nocapture measure`.
#[test]
#[ignore = "a measurement on a report you name with ECHELON_REPORT"]
fn measure_existing_report() {
    let path = PathBuf::from(std::env::var_os("ECHELON_REPORT").expect("set ECHELON_REPORT"));
    let (fps, ms) = play_and_check(&path);
    eprintln!(
        "{}: {fps:.0} frames per second, {ms:.2} ms to draw one (headless)",
        path.display()
    );
}
