//! The live dashboard (`fleet collector --dashboard ADDR`, `fleet up
//! --dashboard`): one self-contained page (`dashboard.html`) served over
//! HTTP on ADDR, fed live over a WebSocket by the collector's Foxglove
//! server ([`super::LiveFeed`]; the page speaks Foxglove's WebSocket
//! protocol and reads the JSON channels `/agent/K/state`, `/agent/K/stats`
//! and `/reference`). It draws with the report's replay drawing
//! ([`echelon_report::replay`], embedded at build time: the same script and
//! style sheet as `report.html`), fed the robots' states as they arrive
//! instead of a recorded run; beside it, per robot, its link state, state
//! age, odometry and fix age, ‖e‖, safety activity and saturation.
//!
//! Its **Stop all** and **Resume** buttons put the fleet-wide stop and
//! resume as `fleet stop` / `fleet resume` do ([`operator`]): the page POSTs
//! `/stop` or `/resume` with the operator token, and the dashboard's
//! operator asks the robots' latches for the command number, puts the
//! command and waits for the acknowledgements, which the answer reports.
//! The token is the fleet's operator token ([`crate::token`]: the
//! collector's `ECHELON_OPERATOR_TOKEN`, which `fleet up` sets, else a
//! random one), printed on stderr at start (the page's URL with
//! `?token=…`); the resumes the page puts are signed with it, so the
//! robots obey them. Without it the page is read-only and the server
//! refuses the POST (403). In secure mode without the `operator`
//! certificate the buttons are not offered: the page says why and the
//! server refuses the POST (503).

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::time::Duration;

use echelon::formation::Leader;
use echelon_mcap::scene::SceneSpec;

use crate::FleetError;
use crate::command::Order;
use crate::net::NetOptions;
use crate::token::OperatorToken;

mod operator;

use operator::{Operator, Refused};

/// The page's template.
const PAGE: &str = include_str!("dashboard.html");
/// Longest request accepted, bytes.
const MAX_REQUEST: usize = 8192;

/// The dashboard's HTTP server: its address and its token.
#[derive(Debug)]
pub struct Dashboard {
    addr: SocketAddr,
    token: OperatorToken,
}

/// The page's configuration: the WebSocket's address, the scene in the
/// replay drawing's terms (agents with their leaders and colours, the
/// reference path flat, the safety filter), and whether the buttons are
/// offered (`operator`: `{"ok": true}`, or `{"ok": false, "why": …}`).
fn config(ws: &str, scene: &SceneSpec, operator: Result<&str, &Refused>) -> serde_json::Value {
    let agents: Vec<serde_json::Value> = scene
        .leaders
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let leader = match l {
                Leader::Reference => -1,
                Leader::Agent(j) => *j as i64,
            };
            serde_json::json!({
                "name": (i + 1).to_string(),
                "leader": leader,
                "color": echelon_report::replay::agent_color(i),
            })
        })
        .collect();
    let safety = scene.safety_radius.map(
        |radius| serde_json::json!({"radius": radius, "l": scene.l, "obstacles": scene.obstacles}),
    );
    let path: Vec<f64> = scene.path.iter().flatten().copied().collect();
    let operator = match operator {
        Ok(identity) => serde_json::json!({"ok": true, "identity": identity}),
        Err(Refused(why)) => serde_json::json!({"ok": false, "why": why}),
    };
    serde_json::json!({
        "ws": ws,
        "agents": agents,
        "path": path,
        "safety": safety,
        "operator": operator,
    })
}

/// The page: the template with the style sheet, the drawing's script and
/// `config` filled in.
fn page(config: &serde_json::Value, safety: bool) -> String {
    // `<` only occurs inside JSON strings: escaped, nothing can end the
    // script early.
    let json = config.to_string().replace('<', "\\u003c");
    PAGE.replacen("/*STYLE*/", echelon_report::replay::STYLE, 1)
        .replacen("/*DRAWING*/", &echelon_report::replay::drawing(safety), 1)
        .replacen("/*CONFIG*/null", &json, 1)
}

impl Dashboard {
    /// Serves the page on `addr` (port 0: any free port), fed from the
    /// Foxglove server at `ws` (`ws://HOST:PORT`), drawing `scene`; its
    /// buttons stop and resume fleet `fleet`, joined as the collector is
    /// (`net`: `operator::operator_net`), for whoever gives `token` (the
    /// fleet's operator token, which signs its resumes).
    pub fn start(
        addr: SocketAddr,
        ws: &str,
        scene: &SceneSpec,
        fleet: &str,
        net: &NetOptions,
        token: OperatorToken,
    ) -> Result<Dashboard, FleetError> {
        let listener = TcpListener::bind(addr)
            .map_err(|e| FleetError::Config(format!("dashboard {addr}: {e}")))?;
        let bound = listener
            .local_addr()
            .map_err(|e| FleetError::Config(format!("dashboard {addr}: {e}")))?;
        let mut operator = Operator::start(fleet, net, token.clone());
        if let Err(Refused(why)) = &operator {
            eprintln!("dashboard: {why}");
        }
        let config = config(ws, scene, operator.as_ref().map(|o| o.identity()));
        let page = page(&config, scene.safety_radius.is_some());
        let secret = token.to_hex();
        std::thread::Builder::new()
            .name("dashboard".into())
            .spawn(move || {
                for stream in listener.incoming().flatten() {
                    // One request per connection, answered at once (an
                    // order once acknowledged, at most about a second); a
                    // client that sends nothing is dropped after a second.
                    let _ = serve(stream, &page, &secret, &mut operator);
                }
            })
            .map_err(|e| FleetError::Config(format!("dashboard: no thread: {e}")))?;
        Ok(Dashboard { addr: bound, token })
    }

    /// The page's URL with the operator token.
    pub fn operator_url(&self) -> String {
        format!("http://{}/?token={}", self.addr, self.token.to_hex())
    }
}

/// Answers one HTTP request: `GET /` the page, `POST /stop` and `POST
/// /resume` with header `X-Echelon-Token` the order given by `operator`
/// (its [`operator::Outcome`] as JSON; 403 without the token, 503 with why
/// when it cannot), anything else 404.
fn serve(
    stream: TcpStream,
    page: &str,
    token: &str,
    operator: &mut Result<Operator, Refused>,
) -> std::io::Result<()> {
    stream.set_read_timeout(Some(Duration::from_secs(1)))?;
    let mut reader = BufReader::new(stream.try_clone()?.take(MAX_REQUEST as u64));
    let mut line = String::new();
    reader.read_line(&mut line)?;
    let mut parts = line.split_whitespace();
    let (method, target) = (parts.next().unwrap_or(""), parts.next().unwrap_or(""));
    let mut given = None;
    loop {
        let mut header = String::new();
        if reader.read_line(&mut header)? == 0 || header.trim().is_empty() {
            break;
        }
        if let Some((name, value)) = header.split_once(':')
            && name.trim().eq_ignore_ascii_case("x-echelon-token")
        {
            given = Some(value.trim().to_owned());
        }
    }
    let path = target.split('?').next().unwrap_or("");
    let (status, kind, body) = match (method, path) {
        ("GET", "/") => ("200 OK", "text/html; charset=utf-8", page.to_owned()),
        ("POST", "/stop" | "/resume") => {
            if !given.as_deref().is_some_and(|g| same(g, token)) {
                (
                    "403 Forbidden",
                    "text/plain",
                    "refused: no operator token".to_owned(),
                )
            } else {
                let order = if path == "/stop" {
                    Order::Stop
                } else {
                    Order::Resume
                };
                match operator
                    .as_mut()
                    .map_err(|r| r.0.clone())
                    .and_then(|o| o.order(order))
                {
                    Ok(outcome) => (
                        "200 OK",
                        "application/json",
                        serde_json::to_string(&outcome).unwrap_or_default(),
                    ),
                    Err(why) => ("503 Service Unavailable", "text/plain", why),
                }
            }
        }
        _ => ("404 Not Found", "text/plain", "not found".to_owned()),
    };
    let mut stream = stream;
    write!(
        stream,
        "HTTP/1.1 {status}\r\nContent-Type: {kind}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n{body}",
        body.len()
    )?;
    stream.flush()
}

/// `a == b` in time independent of where they differ.
fn same(a: &str, b: &str) -> bool {
    a.len() == b.len() && a.bytes().zip(b.bytes()).fold(0u8, |d, (x, y)| d | (x ^ y)) == 0
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use std::sync::{Arc, Mutex};

    use zenoh::Wait;

    use super::*;
    use crate::command::{FleetCommand, Latch};
    use crate::keys::Keys;
    use crate::net::Secure;
    use crate::role::Member;

    fn request(addr: SocketAddr, text: &str) -> String {
        let mut s = TcpStream::connect(addr).unwrap();
        s.write_all(text.as_bytes()).unwrap();
        let mut out = String::new();
        s.read_to_string(&mut out).unwrap();
        out
    }

    /// The body of an HTTP answer.
    fn body(answer: &str) -> &str {
        answer.split_once("\r\n\r\n").unwrap().1
    }

    fn scene() -> SceneSpec {
        SceneSpec {
            leaders: vec![Leader::Reference, Leader::Agent(0)],
            l: vec![0.1, 0.2],
            safety_radius: Some(0.3),
            obstacles: vec![[1.0, 2.0, 0.25]],
            path: vec![[0.0, 0.0], [1.0, 0.5]],
        }
    }

    /// The configuration embedded in a served page.
    fn embedded(page: &str) -> serde_json::Value {
        let at = page.find("const CONFIG = ").unwrap() + "const CONFIG = ".len();
        let end = at + page[at..].find(";\n").unwrap();
        serde_json::from_str(&page[at..end]).unwrap()
    }

    fn free_port() -> u16 {
        std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port()
    }

    /// The page embeds the report's replay drawing and style sheet and the
    /// scene in its terms; a stop or resume goes through only with the
    /// token, and then as `fleet stop` puts one: numbered one past the
    /// highest number a robot's latch answers (here a resume numbered 7,
    /// as after a `fleet stop` then `fleet resume`), by `operator`, and
    /// acknowledged by the robot.
    #[test]
    fn orders_need_the_token_and_follow_the_latches_numbers() {
        let fleet = format!("dash{}", free_port());
        let keys = Keys::new(&fleet);
        // The fleet: one robot's latch, resumed at 7, obeying what it hears.
        let port = free_port();
        let endpoint = format!("tcp/127.0.0.1:{port}");
        let fleet_net = NetOptions {
            listen: vec![endpoint.clone()],
            ..NetOptions::default()
        };
        let session = crate::net::open(&fleet_net).unwrap();
        let token = OperatorToken::random().unwrap();
        let latch = Arc::new(Mutex::new(Latch::with_token(Some(token.clone()))));
        latch
            .lock()
            .unwrap()
            .on_command(FleetCommand::new(Order::Stop, 6, "operator", "cli"));
        latch
            .lock()
            .unwrap()
            .on_command(FleetCommand::new(Order::Resume, 7, "operator", "cli").signed(&token));
        assert!(!latch.lock().unwrap().stopped());
        let heard = Arc::new(Mutex::new(Vec::new()));
        let (l, h) = (latch.clone(), heard.clone());
        let _sub = session
            .declare_subscriber(keys.command())
            .callback(move |s| {
                let bytes = s.payload().to_bytes().into_owned();
                l.lock().unwrap().on_payload(&bytes);
                h.lock()
                    .unwrap()
                    .push(FleetCommand::decode(&bytes).unwrap());
            })
            .wait()
            .unwrap();
        let key = keys.latch(&Member::Robot(1).liveliness());
        let (l, reply_key) = (latch.clone(), key.clone());
        let _latch = session
            .declare_queryable(key)
            .callback(move |q| {
                let answer = l.lock().unwrap().latched().encode();
                let _ = q.reply(reply_key.clone(), answer).wait();
            })
            .wait()
            .unwrap();

        // The collector listens there too: the dashboard's operator joins it.
        let collector = NetOptions {
            listen: vec![endpoint],
            ..NetOptions::default()
        };
        let d = Dashboard::start(
            "127.0.0.1:0".parse().unwrap(),
            "ws://x:1",
            &scene(),
            &fleet,
            &collector,
            token.clone(),
        )
        .unwrap();
        let page = request(d.addr, "GET / HTTP/1.1\r\n\r\n");
        assert!(page.starts_with("HTTP/1.1 200"), "{page}");
        assert!(page.contains(&echelon_report::replay::drawing(true)));
        assert!(page.contains(echelon_report::replay::STYLE));
        assert!(!page.contains("/*"), "every placeholder filled");
        let c = embedded(&page);
        assert_eq!(c["ws"], "ws://x:1");
        assert_eq!(c["agents"][1]["leader"], 0);
        assert_eq!(c["agents"][0]["leader"], -1);
        assert_eq!(
            c["agents"][1]["color"],
            echelon_report::replay::agent_color(1)
        );
        assert_eq!(c["path"], serde_json::json!([0.0, 0.0, 1.0, 0.5]));
        assert_eq!(c["safety"]["l"], serde_json::json!([0.1, 0.2]));
        assert_eq!(c["operator"]["ok"], true);

        for bad in ["", "X-Echelon-Token: nope\r\n"] {
            let r = request(d.addr, &format!("POST /stop HTTP/1.1\r\n{bad}\r\n"));
            assert!(r.starts_with("HTTP/1.1 403"), "{r}");
        }
        assert!(heard.lock().unwrap().is_empty());
        let good = format!("X-Echelon-Token: {}\r\n", d.token.to_hex());
        let order = |what: &str| {
            let started = std::time::Instant::now();
            loop {
                let r = request(d.addr, &format!("POST /{what} HTTP/1.1\r\n{good}\r\n"));
                if !r.contains("try again") || started.elapsed() > Duration::from_secs(20) {
                    return r;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
        };
        let r = order("stop");
        assert!(r.starts_with("HTTP/1.1 200"), "{r}");
        let outcome: serde_json::Value = serde_json::from_str(body(&r)).unwrap();
        assert_eq!(outcome["command"]["seq"], 8, "{outcome}");
        assert_eq!(outcome["command"]["by"], "operator");
        assert_eq!(outcome["robots"], serde_json::json!(["robot/1"]));
        assert_eq!(outcome["acknowledged"], serde_json::json!(["robot/1"]));
        assert!(latch.lock().unwrap().stopped());
        let r = order("resume");
        assert!(r.starts_with("HTTP/1.1 200"), "{r}");
        assert!(!latch.lock().unwrap().stopped());
        let heard = heard.lock().unwrap();
        assert_eq!(
            heard.iter().map(|c| (c.order, c.seq)).collect::<Vec<_>>(),
            [(Order::Stop, 8), (Order::Resume, 9)]
        );
        // The page's resume is signed with the token.
        assert!(heard[1].verified_by(&token), "{:?}", heard[1]);
        assert!(request(d.addr, "GET /x HTTP/1.1\r\n\r\n").starts_with("HTTP/1.1 404"));
        assert_eq!(d.token.to_hex().len(), 32);
        assert!(d.operator_url().ends_with(&token.to_hex()));
    }

    /// Secure mode without the `operator` certificate: the page says why
    /// the buttons are not offered, and the server refuses the order even
    /// with the token.
    #[test]
    fn in_secure_mode_without_the_operator_identity_the_buttons_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let net = NetOptions {
            secure: Some(Secure {
                dir: dir.path().to_path_buf(),
                identity: Member::Collector.identity(),
                robots: 2,
                ros2: Vec::new(),
            }),
            ..NetOptions::default()
        };
        let d = Dashboard::start(
            "127.0.0.1:0".parse().unwrap(),
            "ws://x:1",
            &scene(),
            "lab",
            &net,
            OperatorToken::random().unwrap(),
        )
        .unwrap();
        let page = request(d.addr, "GET / HTTP/1.1\r\n\r\n");
        let c = embedded(&page);
        assert_eq!(c["operator"]["ok"], false);
        let why = c["operator"]["why"].as_str().unwrap();
        assert!(
            why.contains("operator.pem") && why.contains("fleet certs"),
            "{why}"
        );
        let good = format!("X-Echelon-Token: {}\r\n", d.token.to_hex());
        let r = request(d.addr, &format!("POST /stop HTTP/1.1\r\n{good}\r\n"));
        assert!(r.starts_with("HTTP/1.1 503"), "{r}");
        assert_eq!(body(&r), why);
    }
}
