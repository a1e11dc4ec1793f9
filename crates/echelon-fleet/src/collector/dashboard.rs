//! The live dashboard (`fleet collector --dashboard ADDR`, `fleet up
//! --dashboard`): one self-contained page (`dashboard.html`) served over
//! HTTP on ADDR, fed live over a WebSocket by the collector's Foxglove
//! server ([`super::LiveFeed`]; the page speaks Foxglove's WebSocket
//! protocol and reads the JSON channels `/agent/K/state` and
//! `/agent/K/stats`): the robots moving on the reference path and
//! obstacles, and per robot its link state, state age, ‖e‖, safety activity
//! and saturation.
//!
//! Its **Stop all** and **Resume** buttons put the fleet-wide stop and
//! resume of `fleet stop` / `fleet resume` ([`crate::command`]): the page
//! POSTs `/stop` or `/resume` with the operator token, and the collector
//! puts the command on the fleet's command key at its next tick (every
//! [`TICK`] while the dashboard runs), numbered one past the highest it has
//! seen. The token is random, printed on stderr at start (the page's URL
//! with `?token=…`); without it the page is read-only and the server
//! refuses the POST (403).

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::time::Duration;

use echelon_mcap::scene::SceneSpec;

use crate::FleetError;
use crate::command::Order;

/// How often the collector looks for a button's command while the
/// dashboard runs, s.
pub const TICK: f64 = 0.005;
/// The page.
const PAGE: &str = include_str!("dashboard.html");
/// Longest request accepted, bytes.
const MAX_REQUEST: usize = 8192;

/// The dashboard's HTTP server: its address, its token, and the orders its
/// buttons gave.
#[derive(Debug)]
pub struct Dashboard {
    addr: SocketAddr,
    token: String,
    orders: Receiver<Order>,
}

/// A random operator token (128 bits from the OS, hexadecimal).
fn random_token() -> Result<String, FleetError> {
    let mut bytes = [0u8; 16];
    std::fs::File::open("/dev/urandom")
        .and_then(|mut f| f.read_exact(&mut bytes))
        .map_err(FleetError::io(std::path::Path::new("/dev/urandom")))?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

impl Dashboard {
    /// Serves the page on `addr` (port 0: any free port), fed from the
    /// Foxglove server at `ws` (`ws://HOST:PORT`), drawing `scene`.
    pub fn start(addr: SocketAddr, ws: &str, scene: &SceneSpec) -> Result<Dashboard, FleetError> {
        let listener = TcpListener::bind(addr)
            .map_err(|e| FleetError::Config(format!("dashboard {addr}: {e}")))?;
        let bound = listener
            .local_addr()
            .map_err(|e| FleetError::Config(format!("dashboard {addr}: {e}")))?;
        let token = random_token()?;
        let config = serde_json::json!({
            "ws": ws,
            "robots": scene.leaders.len(),
            "path": scene.path,
            "obstacles": scene.obstacles,
            "safety_radius": scene.safety_radius,
        });
        let page = PAGE.replace("/*CONFIG*/null", &config.to_string());
        let (tx, orders) = channel();
        let secret = token.clone();
        std::thread::Builder::new()
            .name("dashboard".into())
            .spawn(move || {
                for stream in listener.incoming().flatten() {
                    // One request per connection, answered at once; a
                    // client that sends nothing is dropped after a second.
                    let _ = serve(stream, &page, &secret, &tx);
                }
            })
            .map_err(|e| FleetError::Config(format!("dashboard: no thread: {e}")))?;
        Ok(Dashboard {
            addr: bound,
            token,
            orders,
        })
    }

    /// The page's URL with the operator token.
    pub fn operator_url(&self) -> String {
        format!("http://{}/?token={}", self.addr, self.token)
    }

    /// The next order a button gave, if any.
    pub fn order(&self) -> Option<Order> {
        self.orders.try_recv().ok()
    }
}

/// Answers one HTTP request: `GET /` the page, `POST /stop` and `POST
/// /resume` with header `X-Echelon-Token` the order (403 without the
/// token), anything else 404.
fn serve(
    stream: TcpStream,
    page: &str,
    token: &str,
    orders: &Sender<Order>,
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
            if given.as_deref().is_some_and(|g| same(g, token)) {
                let order = if path == "/stop" {
                    Order::Stop
                } else {
                    Order::Resume
                };
                let _ = orders.send(order);
                ("200 OK", "text/plain", order.name().to_owned())
            } else {
                (
                    "403 Forbidden",
                    "text/plain",
                    "refused: no operator token".to_owned(),
                )
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

    use super::*;

    fn request(addr: SocketAddr, text: &str) -> String {
        let mut s = TcpStream::connect(addr).unwrap();
        s.write_all(text.as_bytes()).unwrap();
        let mut out = String::new();
        s.read_to_string(&mut out).unwrap();
        out
    }

    /// The page is served with its configuration; a stop or resume goes
    /// through only with the token.
    #[test]
    fn orders_need_the_token() {
        let scene = SceneSpec {
            leaders: vec![echelon::formation::Leader::Reference],
            safety_radius: None,
            obstacles: Vec::new(),
            path: vec![[0.0, 0.0], [1.0, 0.0]],
        };
        let d = Dashboard::start("127.0.0.1:0".parse().unwrap(), "ws://x:1", &scene).unwrap();
        let page = request(d.addr, "GET / HTTP/1.1\r\n\r\n");
        assert!(page.starts_with("HTTP/1.1 200"), "{page}");
        assert!(page.contains("\"ws\":\"ws://x:1\""), "config embedded");
        for bad in ["", "X-Echelon-Token: nope\r\n"] {
            let r = request(d.addr, &format!("POST /stop HTTP/1.1\r\n{bad}\r\n"));
            assert!(r.starts_with("HTTP/1.1 403"), "{r}");
        }
        assert!(d.order().is_none());
        let good = format!("X-Echelon-Token: {}\r\n", d.token);
        let r = request(d.addr, &format!("POST /stop HTTP/1.1\r\n{good}\r\n"));
        assert!(r.starts_with("HTTP/1.1 200"), "{r}");
        let r = request(d.addr, &format!("POST /resume HTTP/1.1\r\n{good}\r\n"));
        assert!(r.starts_with("HTTP/1.1 200"), "{r}");
        std::thread::sleep(Duration::from_millis(50));
        assert_eq!(d.order(), Some(Order::Stop));
        assert_eq!(d.order(), Some(Order::Resume));
        assert!(request(d.addr, "GET /x HTTP/1.1\r\n\r\n").starts_with("HTTP/1.1 404"));
        assert_eq!(d.token.len(), 32);
        assert!(d.operator_url().ends_with(&d.token));
    }
}
