//! Retries of S3 requests: which failures may pass, how long to wait, and a count.
//!
//! A request is retried when the server could not be reached, the connection broke, the
//! request timed out, or the server answered 5xx, 408 or 429; never on an answer that will
//! not change (not found, already exists, refused credentials, another 4xx). Waits grow
//! from 0.2 s to 8 s with jitter (so that many clients do not return at once), ten retries
//! in about 30 s: long enough for a server restart, short enough to fail a run clearly.
//! While no connection to the endpoint has ever been made, a refused connection gets two
//! retries, so that a wrong endpoint fails within a second. Every retry is logged at `warn`
//! with the request and the error (at `debug` before the server has ever answered: the
//! one-line refusal that follows says it all). Once a request has spent all its retries, the
//! server is taken to be down: later requests that fail are not retried until one passes, so
//! a long outage ends a run after one round of retries, not one round per request.
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use crate::error::{Error, Result};

/// Retries of a request once the server has answered, and before it ever has.
pub const RETRIES: u32 = 10;
pub const RETRIES_UNREACHED: u32 = 2;

/// How long one request may take (`IDREX_S3_TIMEOUT`, seconds; 300 by default: a large
/// upload over a slow link must fit).
pub fn request_timeout() -> Result<Duration> {
    match std::env::var("IDREX_S3_TIMEOUT") {
        Err(_) => Ok(Duration::from_secs(300)),
        Ok(v) => match v.trim().parse::<f64>() {
            Ok(s) if s.is_finite() && s > 0.0 && s <= 86_400.0 => Ok(Duration::from_secs_f64(s)),
            _ => Err(Error::Invalid(format!("IDREX_S3_TIMEOUT is '{v}': set it to a number of seconds between 0 and 86400"))),
        },
    }
}

/// The wait before retry `n` (0-based): 0.2 s doubling up to 8 s, times a jitter in [0.5, 1).
pub fn backoff(n: u32, jitter: f64) -> Duration {
    let base = (0.2 * 2f64.powi(n.min(16) as i32)).min(8.0);
    Duration::from_secs_f64(base * (0.5 + 0.5 * jitter.clamp(0.0, 1.0)))
}

/// Whether a failed request may succeed when sent again.
pub fn transient(e: &object_store::Error) -> bool {
    use object_store::Error as E;
    match e {
        E::Generic { source, .. } => {
            let mut s: Option<&(dyn std::error::Error + 'static)> = Some(source.as_ref());
            while let Some(err) = s {
                if err.downcast_ref::<object_store::client::HttpError>().is_some() {
                    return true; // connect, send, timeout, interrupted or cut-off body
                }
                s = err.source();
            }
            transient_status(&source.to_string())
        }
        _ => false,
    }
}

/// Whether a request failed because nothing answered at the endpoint (refused, no route,
/// no such host): the one failure that says nothing about whether a server is there.
fn unreachable(e: &object_store::Error) -> bool {
    let object_store::Error::Generic { source, .. } = e else { return false };
    let mut s: Option<&(dyn std::error::Error + 'static)> = Some(source.as_ref());
    while let Some(err) = s {
        if let Some(h) = err.downcast_ref::<object_store::client::HttpError>() {
            return matches!(h.kind(), object_store::client::HttpErrorKind::Connect);
        }
        s = err.source();
    }
    false
}

/// From the text of an answer object_store does not type: a 5xx, 408 or 429 status.
fn transient_status(text: &str) -> bool {
    let Some(i) = text.find("status code: ") else { return false };
    let code: String = text[i + 13..].chars().take(3).collect();
    code.starts_with('5') || code == "408" || code == "429"
}

/// Whether the server has answered, and how many retries were made: one per client.
#[derive(Debug, Default)]
pub struct Retries {
    reached: AtomicBool,
    /// A request spent all its retries and none has passed since.
    down: AtomicBool,
    count: AtomicU64,
}

impl Retries {
    /// Retries made so far.
    pub fn count(&self) -> u64 {
        self.count.load(Ordering::Relaxed)
    }

    /// Runs `attempt` until it succeeds, fails for good, or the retries are spent; `url` and
    /// `what` name the request in the log.
    pub fn run<T>(
        &self,
        url: &str,
        what: &str,
        attempt: impl FnMut() -> std::result::Result<T, object_store::Error>,
    ) -> std::result::Result<T, object_store::Error> {
        self.run_waiting(url, what, attempt, &std::thread::sleep)
    }

    fn run_waiting<T>(
        &self,
        url: &str,
        what: &str,
        mut attempt: impl FnMut() -> std::result::Result<T, object_store::Error>,
        sleep: &dyn Fn(Duration),
    ) -> std::result::Result<T, object_store::Error> {
        let mut n = 0;
        loop {
            let e = match attempt() {
                Ok(v) => {
                    self.reached.store(true, Ordering::Relaxed);
                    self.down.store(false, Ordering::Relaxed);
                    return Ok(v);
                }
                Err(e) => e,
            };
            if !unreachable(&e) {
                self.reached.store(true, Ordering::Relaxed);
            }
            // A server that outlasted a whole round of retries is down until a request passes:
            // the next failing ones fail at once, so a run ends within one round, not one each.
            if !transient(&e) || self.down.load(Ordering::Relaxed) {
                return Err(e);
            }
            let reached = self.reached.load(Ordering::Relaxed);
            let limit = if reached { RETRIES } else { RETRIES_UNREACHED };
            if n >= limit {
                self.down.store(reached, Ordering::Relaxed);
                return Err(e);
            }
            let wait = backoff(n, jitter());
            n += 1;
            self.count.fetch_add(1, Ordering::Relaxed);
            let line = format!("{url} {what}: {}; retry {n} of {limit} in {:.1} s", clean(&e), wait.as_secs_f64());
            // Before the server has ever answered, the refusal that follows says it all.
            if reached {
                tracing::warn!("{line}");
            } else {
                tracing::debug!("{line}");
            }
            sleep(wait);
        }
    }
}

/// A number in [0, 1) that differs between calls and processes (waits only, never bytes).
fn jitter() -> f64 {
    use std::hash::{BuildHasher, Hasher};
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u128(std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default().as_nanos());
    (h.finish() >> 11) as f64 / (1u64 << 53) as f64
}

/// An object_store error's text without the request details it sometimes carries (which can
/// include signed URLs), on one line.
pub(super) fn clean(e: &(dyn std::error::Error + 'static)) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        let t = s.to_string();
        if !text.contains(&t) {
            text = format!("{text}: {t}");
        }
        source = s.source();
    }
    let text = text.replace('\n', " ");
    // Signed query strings never belong in output.
    let text = match text.find("X-Amz-") {
        Some(i) => format!("{}…", &text[..i]),
        None => text,
    };
    text.chars().take(300).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A transport failure of `kind`, as object_store reports it.
    fn http(kind: object_store::client::HttpErrorKind) -> object_store::Error {
        object_store::Error::Generic {
            store: "S3",
            source: Box::new(object_store::client::HttpError::new(kind, std::io::Error::other("transport"))),
        }
    }

    #[test]
    fn waits_double_to_a_ceiling_and_the_whole_budget_outlasts_a_restart() {
        assert_eq!(backoff(0, 1.0), Duration::from_secs_f64(0.2));
        assert_eq!(backoff(3, 1.0), Duration::from_secs_f64(1.6));
        assert_eq!(backoff(9, 1.0), Duration::from_secs(8));
        assert_eq!(backoff(u32::MAX, 0.0), Duration::from_secs(4));
        let least: f64 = (0..RETRIES).map(|n| backoff(n, 0.0).as_secs_f64()).sum();
        let most: f64 = (0..RETRIES).map(|n| backoff(n, 1.0).as_secs_f64()).sum();
        assert!(least > 10.0 && most < 45.0, "{least} {most}");
        let unreached: f64 = (0..RETRIES_UNREACHED).map(|n| backoff(n, 1.0).as_secs_f64()).sum();
        assert!(unreached < 1.0, "{unreached}");
    }

    #[test]
    fn only_failures_that_may_pass_are_retried() {
        let timeout = http(object_store::client::HttpErrorKind::Timeout);
        assert!(transient(&timeout) && !unreachable(&timeout));
        let generic = |text: &str| object_store::Error::Generic { store: "S3", source: text.to_string().into() };
        assert!(transient(&generic("Server returned non-2xx status code: 503 Service Unavailable: SlowDown")));
        assert!(transient(&generic("Server returned non-2xx status code: 429 Too Many Requests: ")));
        assert!(!transient(&generic("Server returned non-2xx status code: 400 Bad Request: ")));
        assert!(!transient(&generic("Received redirect without LOCATION")));
        assert!(transient(&http(object_store::client::HttpErrorKind::Connect)));
        assert!(!transient(&object_store::Error::NotFound { path: "x".into(), source: "gone".into() }));
        assert!(!transient(&object_store::Error::PermissionDenied { path: "x".into(), source: "SignatureDoesNotMatch".into() }));
    }

    #[test]
    fn a_server_that_never_answered_is_given_up_on_quickly_and_retries_are_counted() {
        let r = Retries::default();
        let refused = || http(object_store::client::HttpErrorKind::Connect);
        let mut tries = 0;
        assert!(
            r.run::<()>("s3://b", "reading x", || {
                tries += 1;
                Err(refused())
            })
            .is_err()
        );
        assert_eq!((tries, r.count()), (1 + RETRIES_UNREACHED as usize, RETRIES_UNREACHED as u64));
        // Once it has answered, a failure that passes is ridden out.
        assert_eq!(r.run("s3://b", "reading x", || Ok(1)).unwrap(), 1);
        let mut tries = 0;
        let got = r.run("s3://b", "reading x", || {
            tries += 1;
            if tries < 4 { Err(refused()) } else { Ok(7) }
        });
        assert_eq!(got.unwrap(), 7);
        assert_eq!(r.count(), RETRIES_UNREACHED as u64 + 3);
        // Not found is an answer: no retry.
        let mut tries = 0;
        let e = r.run::<()>("s3://b", "reading x", || {
            tries += 1;
            Err(object_store::Error::NotFound { path: "x".into(), source: "gone".into() })
        });
        assert!(e.is_err() && tries == 1);
    }

    #[test]
    fn after_one_request_spends_its_retries_the_next_failures_are_not_retried_until_one_passes() {
        let r = Retries::default();
        let no_wait = |_: Duration| {};
        let refused = || http(object_store::client::HttpErrorKind::Request);
        let mut tries = 0;
        assert!(
            r.run_waiting::<()>(
                "s3://b",
                "x",
                || {
                    tries += 1;
                    Err(refused())
                },
                &no_wait
            )
            .is_err()
        );
        assert_eq!(tries, 1 + RETRIES as usize);
        let mut tries = 0;
        assert!(
            r.run_waiting::<()>(
                "s3://b",
                "y",
                || {
                    tries += 1;
                    Err(refused())
                },
                &no_wait
            )
            .is_err()
        );
        assert_eq!(tries, 1, "the server is down: no second round");
        assert_eq!(r.run_waiting("s3://b", "z", || Ok(1), &no_wait).unwrap(), 1);
        let mut tries = 0;
        let back = r.run_waiting(
            "s3://b",
            "w",
            || {
                tries += 1;
                if tries < 3 { Err(refused()) } else { Ok(2) }
            },
            &no_wait,
        );
        assert_eq!((back.unwrap(), tries), (2, 3), "back up: failures are retried again");
    }
}
