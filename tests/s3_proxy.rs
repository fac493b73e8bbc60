//! A TCP proxy in front of the test's S3 server that injects faults, one decision per
//! request: it adds `Connection: close` to every request it passes, so that each
//! connection carries one request and a fault hits requests, not pooled connections.
//!
//! Faults: the connection is dropped before the request is read; the server answers
//! 503 SlowDown (as S3 does under load); the request stalls past the client's timeout; the
//! upload is cut off part-way; the answer is cut off part-way. Each is counted when it
//! happened.
//!
//! Which request is faulted, and how, is a function of the seed and the request's position in
//! arrival order only (a plan drawn when the proxy starts), never of a generator shared by
//! requests as they come: the first five faults of the plan are the five kinds in a seeded
//! order, so every kind is drawn in every run that makes a few dozen requests.
#![allow(dead_code)]
use std::io::{Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
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
    stall: Duration,
    /// The fault of each request position (past its end, none).
    plan: Vec<Option<Fault>>,
    seed: u64,
    /// Positions handed out, in arrival order.
    arrivals: AtomicU64,
    requests: AtomicU64,
    injected: [AtomicU64; 5],
    /// A cut upload was planned for a request with no body: the next upload takes it. Which
    /// request arrives at which position depends on timing (two jobs share the proxy), so
    /// without this a run could plan its cuts only on GETs and inject none.
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
            stall,
            plan: plan(seed, rate, stalls, PLANNED),
            seed,
            arrivals: AtomicU64::new(0),
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

/// Requests planned for; later ones pass unfaulted (a run makes a few thousand).
const PLANNED: usize = 1 << 20;

/// splitmix64 of `x`: the proxy's only source of randomness, a pure function.
fn mix(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A uniform draw in [0, 1) for (seed, position, purpose).
fn uniform(seed: u64, position: u64, purpose: u64) -> f64 {
    (mix(mix(seed ^ purpose.wrapping_mul(0xd6e8_feb8_6659_fd93)) ^ position) >> 11) as f64 / (1u64 << 53) as f64
}

/// The fault of each of the first `n` positions: `rate` of them faulted; the first five
/// faults are the five kinds in a seeded order, the rest drawn; past `stalls` stalls, a stall
/// is a 503 instead.
fn plan(seed: u64, rate: f64, stalls: u64, n: usize) -> Vec<Option<Fault>> {
    let mut first = FAULTS;
    for i in (1..first.len()).rev() {
        first.swap(i, (mix(seed ^ i as u64) % (i as u64 + 1)) as usize);
    }
    let (mut faults, mut stalled) = (0usize, 0u64);
    (0..n as u64)
        .map(|pos| {
            if uniform(seed, pos, 0) >= rate {
                return None;
            }
            let f = first.get(faults).copied().unwrap_or(FAULTS[(uniform(seed, pos, 1) * FAULTS.len() as f64) as usize]);
            faults += 1;
            if f == Fault::Stall {
                stalled += 1;
                if stalled > stalls {
                    return Some(Fault::SlowDown);
                }
            }
            Some(f)
        })
        .collect()
}

impl State {
    /// This request's position and planned fault.
    fn arrive(&self) -> (u64, Option<Fault>) {
        let pos = self.arrivals.fetch_add(1, Ordering::Relaxed);
        (pos, self.plan.get(pos as usize).copied().flatten())
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
    let (pos, fault) = s.arrive();
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
        (Some(Fault::CutUpload), Some(len)) => Some((uniform(s.seed, pos, 2) * len.min(4096) as f64) as u64),
        _ => None,
    };
    // Within the status line and headers, which every answer has: a cut always happens.
    let cut_answer = (fault == Some(Fault::CutAnswer)).then(|| 1 + (uniform(s.seed, pos, 3) * 63.0) as u64);
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

/// Run in the suite's binary (`tests`); the cluster binary, which has no test harness, also
/// includes this file.
#[cfg(test)]
mod tests {
    #[allow(unused_imports)]
    use super::*;

    /// The plan is the seed's alone, draws every kind among its first faults, keeps the rate
    /// and the stall budget, and differs between seeds.
    #[test]
    fn the_plan_is_a_function_of_the_seed_and_holds_every_kind() {
        let a = plan(7, 0.2, 4, 20_000);
        assert_eq!(a, plan(7, 0.2, 4, 20_000));
        assert_ne!(a, plan(8, 0.2, 4, 20_000));
        let faulted: Vec<Fault> = a.iter().flatten().copied().collect();
        let share = faulted.len() as f64 / a.len() as f64;
        assert!((0.18..0.22).contains(&share), "{share}");
        for f in FAULTS {
            assert!(faulted[..5].contains(&f), "{f:?} is not among the first five faults");
        }
        assert_eq!(faulted.iter().filter(|f| **f == Fault::Stall).count(), 4);
    }
}
