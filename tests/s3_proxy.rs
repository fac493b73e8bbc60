//! A TCP proxy in front of the test's S3 server that injects faults, one decision per
//! request: it adds `Connection: close` to every request it passes, so that each
//! connection carries one request and a fault hits requests, not pooled connections.
//!
//! Faults: the connection is dropped before the request is read; the server answers
//! 503 SlowDown (as S3 does under load); the request stalls past the client's timeout; the
//! upload is cut off part-way; the answer is cut off part-way. Each is counted when it
//! happened (a cut that falls past the end of a short message is not a fault).
#![allow(dead_code)]
use std::io::{Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    Drop,
    SlowDown,
    Stall,
    CutUpload,
    CutAnswer,
}

pub const FAULTS: [Fault; 5] = [Fault::Drop, Fault::SlowDown, Fault::Stall, Fault::CutUpload, Fault::CutAnswer];

struct State {
    upstream: u16,
    /// Fraction of requests faulted.
    rate: f64,
    stall: Duration,
    /// Stalls left (each costs a client timeout).
    stalls_left: AtomicU64,
    rng: Mutex<u64>,
    requests: AtomicU64,
    injected: [AtomicU64; 5],
    /// A cut upload was drawn for a request with no body: the next upload takes it. Which
    /// request draws which fault depends on timing (two jobs share the proxy), so without this
    /// a run could draw its cuts only on GETs and inject none.
    cut_pending: AtomicBool,
    stop: AtomicBool,
}

pub struct Proxy {
    pub port: u16,
    state: Arc<State>,
}

impl Proxy {
    /// Listens on a free loopback port and forwards to `upstream`, faulting `rate` of the
    /// requests; at most `stalls` of them stall (for `stall` each).
    pub fn start(upstream: u16, rate: f64, stalls: u64, stall: Duration, seed: u64) -> Proxy {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let port = listener.local_addr().unwrap().port();
        let state = Arc::new(State {
            upstream,
            rate,
            stall,
            stalls_left: AtomicU64::new(stalls),
            rng: Mutex::new(seed | 1),
            requests: AtomicU64::new(0),
            injected: Default::default(),
            cut_pending: AtomicBool::new(false),
            stop: AtomicBool::new(false),
        });
        let s = state.clone();
        std::thread::spawn(move || {
            for conn in listener.incoming() {
                if s.stop.load(Ordering::Relaxed) {
                    break;
                }
                let Ok(conn) = conn else { continue };
                let s = s.clone();
                std::thread::spawn(move || serve(&s, conn));
            }
        });
        Proxy { port, state }
    }

    pub fn requests(&self) -> u64 {
        self.state.requests.load(Ordering::Relaxed)
    }

    /// How many faults of each kind happened.
    pub fn injected(&self) -> Vec<(Fault, u64)> {
        FAULTS.iter().map(|f| (*f, self.state.injected[*f as usize].load(Ordering::Relaxed))).collect()
    }

    pub fn total_injected(&self) -> u64 {
        self.injected().iter().map(|(_, n)| n).sum()
    }
}

impl Drop for Proxy {
    fn drop(&mut self) {
        self.state.stop.store(true, Ordering::Relaxed);
        let _ = TcpStream::connect(("127.0.0.1", self.port)); // wakes the accept loop
    }
}

impl State {
    fn next(&self) -> u64 {
        let mut x = self.rng.lock().unwrap();
        // xorshift64*
        *x ^= *x >> 12;
        *x ^= *x << 25;
        *x ^= *x >> 27;
        x.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    fn uniform(&self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }

    fn choose(&self) -> Option<Fault> {
        if self.uniform() >= self.rate {
            return None;
        }
        let f = FAULTS[(self.next() % FAULTS.len() as u64) as usize];
        if f == Fault::Stall && self.stalls_left.fetch_update(Ordering::Relaxed, Ordering::Relaxed, |n| n.checked_sub(1)).is_err() {
            return Some(Fault::SlowDown);
        }
        Some(f)
    }

    fn count(&self, f: Fault) {
        self.injected[f as usize].fetch_add(1, Ordering::Relaxed);
    }
}

/// Reads up to the end of the request head; returns (head, body bytes read past it).
fn read_head(conn: &mut TcpStream) -> Option<(Vec<u8>, Vec<u8>)> {
    let mut buf = Vec::new();
    let mut chunk = [0u8; 8192];
    loop {
        if let Some(i) = buf.windows(4).position(|w| w == b"\r\n\r\n") {
            let rest = buf.split_off(i + 4);
            return Some((buf, rest));
        }
        let n = conn.read(&mut chunk).ok()?;
        if n == 0 || buf.len() > 1 << 20 {
            return None;
        }
        buf.extend_from_slice(&chunk[..n]);
    }
}

/// The head with `Connection: close` in place of any connection header.
fn closing(head: &[u8]) -> Vec<u8> {
    let text = String::from_utf8_lossy(&head[..head.len() - 4]);
    let mut out: Vec<&str> = text.split("\r\n").filter(|l| !l.to_ascii_lowercase().starts_with("connection:")).collect();
    out.push("Connection: close");
    (out.join("\r\n") + "\r\n\r\n").into_bytes()
}

fn serve(s: &State, mut conn: TcpStream) {
    let fault = s.choose();
    if fault == Some(Fault::Drop) {
        s.requests.fetch_add(1, Ordering::Relaxed);
        s.count(Fault::Drop);
        let _ = conn.shutdown(Shutdown::Both);
        return;
    }
    let Some((head, rest)) = read_head(&mut conn) else { return };
    s.requests.fetch_add(1, Ordering::Relaxed);
    match fault {
        Some(Fault::SlowDown) => {
            s.count(Fault::SlowDown);
            let body = "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<Error><Code>SlowDown</Code><Message>Please reduce your request rate.</Message></Error>";
            let _ = write!(
                conn,
                "HTTP/1.1 503 Service Unavailable\r\nContent-Type: application/xml\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
                body.len()
            );
            let _ = conn.shutdown(Shutdown::Both);
            return;
        }
        Some(Fault::Stall) => {
            s.count(Fault::Stall);
            std::thread::sleep(s.stall);
            let _ = conn.shutdown(Shutdown::Both);
            return;
        }
        _ => {}
    }
    let Ok(mut up) = TcpStream::connect(("127.0.0.1", s.upstream)) else {
        let _ = conn.shutdown(Shutdown::Both);
        return;
    };
    if up.write_all(&closing(&head)).is_err() {
        return;
    }
    // Where a cut falls: somewhere in the upload's body (within its declared length), or in
    // the answer's first kilobytes.
    let body = upload_length(&head);
    let fault = match (fault, body) {
        (Some(Fault::CutUpload), None) => {
            s.cut_pending.store(true, Ordering::Relaxed);
            None
        }
        (None, Some(_)) if s.cut_pending.swap(false, Ordering::Relaxed) => Some(Fault::CutUpload),
        (f, _) => f,
    };
    let cut_upload = match (fault, body) {
        (Some(Fault::CutUpload), Some(len)) => Some(s.next() % len.min(4096)),
        _ => None,
    };
    let cut_answer = (fault == Some(Fault::CutAnswer)).then(|| 1 + s.next() % 1024);
    let (mut c2, mut u2) = (conn.try_clone().unwrap(), up.try_clone().unwrap());
    let upload = std::thread::spawn(move || pipe(&rest, &mut c2, &mut u2, cut_upload));
    let answered = pipe(&[], &mut up, &mut conn, cut_answer);
    let _ = conn.shutdown(Shutdown::Both);
    let _ = up.shutdown(Shutdown::Both);
    let uploaded = upload.join().unwrap_or(false);
    if uploaded {
        s.count(Fault::CutUpload);
    }
    if answered {
        s.count(Fault::CutAnswer);
    }
}

/// The declared body length of an upload (PUT or POST with a non-empty body), if the request is one.
fn upload_length(head: &[u8]) -> Option<u64> {
    let text = String::from_utf8_lossy(head);
    let method = text.split(' ').next().unwrap_or("");
    if method != "PUT" && method != "POST" {
        return None;
    }
    let len = text.lines().find_map(|l| {
        let (k, v) = l.split_once(':')?;
        k.trim().eq_ignore_ascii_case("content-length").then(|| v.trim().parse::<u64>().ok()).flatten()
    });
    // A chunked upload declares no length; its body is at least a chunk header long.
    Some(len.unwrap_or(4096)).filter(|&n| n > 0)
}

/// Copies `first` then `from` to `to` until `from` ends; with `cut`, stops after that many
/// bytes and closes both. Returns whether it cut something off.
fn pipe(first: &[u8], from: &mut TcpStream, to: &mut TcpStream, cut: Option<u64>) -> bool {
    let mut left = cut.unwrap_or(u64::MAX);
    let mut chunk = [0u8; 16384];
    let mut data = first.to_vec();
    loop {
        if !data.is_empty() {
            let n = (data.len() as u64).min(left) as usize;
            if to.write_all(&data[..n]).is_err() {
                return false;
            }
            left -= n as u64;
            if n < data.len() {
                let _ = from.shutdown(Shutdown::Both);
                let _ = to.shutdown(Shutdown::Both);
                return true;
            }
        }
        match from.read(&mut chunk) {
            Ok(0) | Err(_) => {
                let _ = to.shutdown(Shutdown::Write);
                return false;
            }
            Ok(n) => data = chunk[..n].to_vec(),
        }
    }
}
