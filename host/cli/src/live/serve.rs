//! The live page of `vltm live --serve`: a small HTTP/1.1 server on the standard library
//! (one thread per connection, `Connection: close`), bound to loopback unless an address is
//! given. Routes:
//!
//! | path | content |
//! |---|---|
//! | `/` | the page (`page.html`: no build step, nothing fetched from elsewhere) |
//! | `/events` | server-sent events: the status JSON after every fold (a comment every 15 s keeps the connection) |
//! | `/status.json` | the latest status JSON |
//! | `/png/<probe>.png` | the probe's current figure (the PNGs `vltm::export::figure` draws) |
//! | `/transient.png` | the capture's summed transient so far |
//!
//! Why no HTTP crate: the page needs four GET routes and one event stream that must reach the
//! browser at every fold (a buffered chunked body would hold events back), and loopback
//! needs no TLS or keep-alive. Requests are read with a 5 s timeout and at most 8 KiB of
//! head; at most 32 connections are served at once, others are closed.

use std::collections::HashMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use vltm::live::{LiveRun, View};

const PAGE: &str = include_str!("page.html");
const MAX_CONNECTIONS: usize = 32;

#[derive(Default)]
struct State {
    version: u64,
    status: String,
    pngs: HashMap<String, Arc<Vec<u8>>>,
    transient: Option<Arc<Vec<u8>>>,
    closed: bool,
}

struct Shared {
    state: Mutex<State>,
    changed: Condvar,
    connections: AtomicUsize,
}

/// The live page's server (see the module docs).
pub(crate) struct Server {
    addr: SocketAddr,
    shared: Arc<Shared>,
}

impl Server {
    /// Binds `spec` (`PORT` → `127.0.0.1:PORT`, or `ADDR:PORT`) and starts serving.
    ///
    /// # Errors
    /// [`vltm::Error::Argument`] (`--serve`) for an address that does not parse or cannot be
    /// bound (a port in use), naming it.
    pub(crate) fn bind(spec: &str) -> vltm::Result<Self> {
        let text = if spec.parse::<u16>().is_ok() {
            format!("127.0.0.1:{spec}")
        } else {
            spec.to_string()
        };
        let addr: SocketAddr = text.parse().map_err(|_| {
            vltm::Error::arg(
                "--serve",
                format!("expected PORT or ADDR:PORT (e.g. 127.0.0.1:8080), found `{spec}`"),
            )
        })?;
        let listener = TcpListener::bind(addr)
            .map_err(|e| vltm::Error::arg("--serve", format!("cannot listen on {addr}: {e}")))?;
        let addr = listener.local_addr().unwrap_or(addr);
        let shared = Arc::new(Shared {
            state: Mutex::new(State {
                status: "{\"rows\":0,\"total\":0,\"done\":false,\"probes\":[]}".into(),
                ..State::default()
            }),
            changed: Condvar::new(),
            connections: AtomicUsize::new(0),
        });
        let s = Arc::clone(&shared);
        std::thread::spawn(move || {
            for conn in listener.incoming() {
                let Ok(conn) = conn else { continue };
                if s.connections.load(Ordering::SeqCst) >= MAX_CONNECTIONS {
                    continue;
                }
                s.connections.fetch_add(1, Ordering::SeqCst);
                let s = Arc::clone(&s);
                std::thread::spawn(move || {
                    let _ = handle(conn, &s);
                    s.connections.fetch_sub(1, Ordering::SeqCst);
                });
            }
        });
        Ok(Self { addr, shared })
    }

    /// The address served.
    pub(crate) fn addr(&self) -> SocketAddr {
        self.addr
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        self.shared.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Publishes a new status, the views' figures and the transient.
    pub(crate) fn publish(&self, mut status: serde_json::Value, views: &[View], run: &LiveRun) {
        let transient = run.transient_png().map(Arc::new);
        let mut st = self.lock();
        st.version += 1;
        status["version"] = st.version.into();
        st.status = status.to_string();
        for v in views {
            if !v.png.is_empty() {
                st.pngs.insert(v.tag.clone(), Arc::new(v.png.clone()));
            }
        }
        if transient.is_some() {
            st.transient = transient;
        }
        drop(st);
        self.shared.changed.notify_all();
    }

    /// Publishes an error (shown on the page).
    pub(crate) fn fail(&self, msg: &str) {
        let mut st = self.lock();
        let mut v: serde_json::Value =
            serde_json::from_str(&st.status).unwrap_or_else(|_| serde_json::json!({}));
        st.version += 1;
        v["error"] = msg.into();
        v["version"] = st.version.into();
        st.status = v.to_string();
        drop(st);
        self.shared.changed.notify_all();
    }

    /// Keeps serving for `d`, then ends the event streams.
    pub(crate) fn linger(&self, d: Duration) {
        std::thread::sleep(d);
        self.lock().closed = true;
        self.shared.changed.notify_all();
    }
}

fn respond(c: &mut TcpStream, code: &str, ty: &str, body: &[u8]) -> std::io::Result<()> {
    write!(
        c,
        "HTTP/1.1 {code}\r\nContent-Type: {ty}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
        body.len()
    )?;
    c.write_all(body)?;
    c.flush()
}

fn handle(conn: TcpStream, s: &Shared) -> std::io::Result<()> {
    conn.set_read_timeout(Some(Duration::from_secs(5)))?;
    let mut reader = BufReader::new(conn.try_clone()?).take(8192);
    let mut line = String::new();
    reader.read_line(&mut line)?;
    // Drain the head (to the blank line).
    loop {
        let mut h = String::new();
        if reader.read_line(&mut h)? == 0 || h == "\r\n" || h == "\n" {
            break;
        }
    }
    let mut c = conn;
    let mut parts = line.split_whitespace();
    let (method, target) = (parts.next().unwrap_or(""), parts.next().unwrap_or(""));
    if method != "GET" {
        return respond(
            &mut c,
            "405 Method Not Allowed",
            "text/plain",
            b"GET only\n",
        );
    }
    let path = target.split('?').next().unwrap_or("");
    let lock = || s.state.lock().unwrap_or_else(|e| e.into_inner());
    match path {
        "/" | "/index.html" => respond(
            &mut c,
            "200 OK",
            "text/html; charset=utf-8",
            PAGE.as_bytes(),
        ),
        "/status.json" => {
            let body = lock().status.clone();
            respond(&mut c, "200 OK", "application/json", body.as_bytes())
        }
        "/transient.png" => match lock().transient.clone() {
            Some(b) => respond(&mut c, "200 OK", "image/png", &b),
            None => respond(&mut c, "404 Not Found", "text/plain", b"no counts yet\n"),
        },
        "/events" => events(c, s),
        p => {
            let png = p
                .strip_prefix("/png/")
                .and_then(|t| t.strip_suffix(".png"))
                .and_then(|t| lock().pngs.get(t).cloned());
            match png {
                Some(b) => respond(&mut c, "200 OK", "image/png", &b),
                None => respond(&mut c, "404 Not Found", "text/plain", b"not found\n"),
            }
        }
    }
}

/// Server-sent events: the status after every change.
fn events(mut c: TcpStream, s: &Shared) -> std::io::Result<()> {
    write!(
        c,
        "HTTP/1.1 200 OK\r\nContent-Type: text/event-stream\r\nCache-Control: no-store\r\nConnection: close\r\n\r\nretry: 1000\n\n"
    )?;
    c.flush()?;
    let mut seen = 0;
    loop {
        let mut st = s.state.lock().unwrap_or_else(|e| e.into_inner());
        let t = Instant::now();
        while st.version == seen && !st.closed && t.elapsed() < Duration::from_secs(15) {
            st = s
                .changed
                .wait_timeout(st, Duration::from_secs(15))
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
        if st.closed {
            return Ok(());
        }
        if st.version == seen {
            drop(st);
            c.write_all(b": ping\n\n")?;
        } else {
            seen = st.version;
            let msg = format!("data: {}\n\n", st.status);
            drop(st);
            c.write_all(msg.as_bytes())?;
        }
        c.flush()?;
    }
}
