//! Reads demonstrations from NPZ files with `obs`, `actions`, `rewards` and
//! `episode_lengths` arrays (the layout of the original D-REX demonstrations).
//!
//! The files hold one observation per step (s_0..s_{T-1}) and no final observation; our
//! trajectories carry s_T too, so the last observation is repeated as s_T. BC reads only
//! (s_t, a_t) pairs and is unaffected; the returns are exact.
use std::io::Read;
use std::path::Path;

use crate::data::{TrajMeta, Trajectory};
use crate::error::{Error, Result};

struct Array {
    shape: Vec<usize>,
    data: Vec<f64>,
}

fn parse_npy(name: &str, bytes: &[u8]) -> std::result::Result<Array, String> {
    if bytes.len() < 12 || &bytes[..6] != b"\x93NUMPY" {
        return Err(format!("{name} is not a .npy array"));
    }
    let (hlen, start): (usize, usize) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 => (u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize, 12),
        v => return Err(format!("{name}: .npy format version {v} is not supported")),
    };
    let header = bytes
        .get(start..start.saturating_add(hlen))
        .and_then(|h| std::str::from_utf8(h).ok())
        .ok_or(format!("{name}: malformed .npy header"))?;
    let field = |key: &str| -> Option<&str> {
        let i = header.find(&format!("'{key}'"))? + key.len() + 2;
        Some(header[i..].trim_start_matches([':', ' ']))
    };
    let descr = field("descr").and_then(|d| d.strip_prefix('\'')).and_then(|d| d.split('\'').next()).ok_or(format!("{name}: no descr"))?;
    if field("fortran_order").is_some_and(|f| f.starts_with("True")) {
        return Err(format!("{name}: Fortran-ordered arrays are not supported"));
    }
    let shape_txt =
        field("shape").and_then(|s| s.strip_prefix('(')).and_then(|s| s.split(')').next()).ok_or(format!("{name}: no shape"))?;
    let shape: Vec<usize> = shape_txt
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse().map_err(|_| format!("{name}: bad shape")))
        .collect::<std::result::Result<_, _>>()?;
    let body = &bytes[start + hlen..];
    let n = shape.iter().try_fold(1usize, |a, &d| a.checked_mul(d)).ok_or(format!("{name}: shape {shape:?} is too large"))?;
    let data: Vec<f64> = match descr {
        "<f8" => body.chunks_exact(8).take(n).map(|c| f64::from_le_bytes(c.try_into().unwrap())).collect(),
        "<f4" => body.chunks_exact(4).take(n).map(|c| f32::from_le_bytes(c.try_into().unwrap()) as f64).collect(),
        "<i8" => body.chunks_exact(8).take(n).map(|c| i64::from_le_bytes(c.try_into().unwrap()) as f64).collect(),
        "<i4" => body.chunks_exact(4).take(n).map(|c| i32::from_le_bytes(c.try_into().unwrap()) as f64).collect(),
        other => return Err(format!("{name}: dtype {other} is not supported (use float32/64 or int32/64)")),
    };
    if data.len() != n {
        return Err(format!("{name}: file is shorter than its shape {shape:?}"));
    }
    Ok(Array { shape, data })
}

/// Reads the episodes of an NPZ demonstration file.
pub fn read(path: &Path, source: &str) -> Result<Vec<Trajectory>> {
    parse(path, &std::fs::read(path).map_err(|e| Error::io(path, e))?, source)
}

/// The episodes of an NPZ file's bytes; `path` names it in every refusal.
pub fn parse(path: &Path, bytes: &[u8], source: &str) -> Result<Vec<Trajectory>> {
    let bad = |m: String| Error::file(path, m);
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes)).map_err(|e| bad(format!("not an NPZ (zip) file: {e}")))?;
    let mut get = |name: &str| -> Result<Array> {
        let mut f = zip
            .by_name(&format!("{name}.npy"))
            .map_err(|_| bad(format!("has no '{name}' array; expected obs, actions, rewards, episode_lengths")))?;
        let mut bytes = Vec::new();
        f.read_to_end(&mut bytes).map_err(|e| Error::io(path, e))?;
        parse_npy(name, &bytes).map_err(bad)
    };
    let (obs, actions, rewards, lengths) = (get("obs")?, get("actions")?, get("rewards")?, get("episode_lengths")?);
    let t = rewards.data.len();
    if obs.shape.len() != 2 || actions.shape.len() != 2 || obs.shape[0] != t || actions.shape[0] != t {
        return Err(bad(format!(
            "obs {:?}, actions {:?} and rewards {:?} do not have one row per step",
            obs.shape, actions.shape, rewards.shape
        )));
    }
    if lengths.data.is_empty() {
        return Err(bad("holds no episodes (episode_lengths is empty)".into()));
    }
    if let Some((e, l)) = lengths.data.iter().enumerate().find(|(_, l)| !(l.fract() == 0.0 && **l >= 1.0)) {
        return Err(bad(format!("episode_lengths[{e}] is {l}; every length must be a whole number of steps, at least 1")));
    }
    let total: f64 = lengths.data.iter().sum();
    if total as usize != t {
        return Err(bad(format!("episode_lengths sum to {total}, but there are {t} steps")));
    }
    for (name, a) in [("obs", &obs), ("actions", &actions), ("rewards", &rewards)] {
        if let Some(i) = a.data.iter().position(|x| !x.is_finite()) {
            return Err(bad(format!("{name} holds a non-finite value ({}) at flat index {i}", a.data[i])));
        }
    }
    let (od, ad) = (obs.shape[1], actions.shape[1]);
    let mut out = Vec::new();
    let mut start = 0;
    for (e, &len) in lengths.data.iter().enumerate() {
        let len = len as usize;
        let rows = start..start + len;
        let mut o: Vec<f32> = obs.data[rows.start * od..rows.end * od].iter().map(|&x| x as f32).collect();
        o.extend_from_within((len - 1) * od..len * od);
        out.push(Trajectory {
            obs_dim: od,
            act_dim: ad,
            obs: o,
            actions: actions.data[rows.start * ad..rows.end * ad].iter().map(|&x| x as f32).collect(),
            rewards: rewards.data[rows.clone()].to_vec(),
            terms: vec![Default::default(); len],
            terminated: false,
            truncated: false,
            meta: TrajMeta { source: source.to_string(), noise: 0.0, seed: e as u64, group: 0 },
        });
        start += len;
    }
    Ok(out)
}
