//! Rollout sets as MCAP files: the artifact the learners read back and the log users open in
//! Foxglove, the `mcap` CLI or Python's `mcap` reader.
//!
//! Layout (JSON messages, each channel with a `jsonschema` schema):
//! - `/episode`: one message when an episode starts: index, source policy, noise level,
//!   seed, group and the first observation s_0.
//! - `/step`: one message per step: episode, t, the observation s_t the action was taken
//!   in, the action, the next observation s_{t+1}, the environment reward and its terms, the
//!   learned reward where there is one (the field is absent otherwise), and the
//!   terminated/truncated flags. Every schema field has exactly one JSON type, as Foxglove's
//!   JSON-schema parser requires.
//! - log_time is simulated time in nanoseconds, monotonic over the whole file (episodes
//!   follow each other), publish_time equals it.
//! - metadata `idrex.rollout` (env, dimensions, dt, format) and `idrex.episodes` (one
//!   JSON entry per episode: start time, length, return, noise, source, seed, how it ended).
use std::collections::BTreeMap;
use std::io::{BufWriter, Seek, Write};
use std::path::Path;

use serde_json::json;

use crate::data::{TrajMeta, Trajectory};
use crate::env::RewardTerms;
use crate::error::{Error, Result};

pub const FORMAT: &str = "idrex-rollout/1";

const EPISODE_SCHEMA: &str = r#"{"type":"object","title":"idrex.Episode","properties":{"episode":{"type":"integer"},"source":{"type":"string"},"noise":{"type":"number"},"seed":{"type":"integer"},"group":{"type":"integer"},"obs":{"type":"array","items":{"type":"number"}}},"required":["episode","source","noise","seed","group","obs"]}"#;
const STEP_SCHEMA: &str = r#"{"type":"object","title":"idrex.Step","properties":{"episode":{"type":"integer"},"t":{"type":"integer"},"obs":{"type":"array","items":{"type":"number"}},"action":{"type":"array","items":{"type":"number"}},"next_obs":{"type":"array","items":{"type":"number"}},"reward":{"type":"number"},"reward_forward":{"type":"number"},"reward_ctrl":{"type":"number"},"reward_survive":{"type":"number"},"learned_reward":{"type":"number"},"terminated":{"type":"boolean"},"truncated":{"type":"boolean"}},"required":["episode","t","obs","action","next_obs","reward","terminated","truncated"]}"#;

/// The step schema of a task with a contact cost (Ant): `reward_contact` too. The other tasks
/// keep the schema above, so their files' bytes are what they were.
const STEP_SCHEMA_CONTACT: &str = r#"{"type":"object","title":"idrex.Step","properties":{"episode":{"type":"integer"},"t":{"type":"integer"},"obs":{"type":"array","items":{"type":"number"}},"action":{"type":"array","items":{"type":"number"}},"next_obs":{"type":"array","items":{"type":"number"}},"reward":{"type":"number"},"reward_forward":{"type":"number"},"reward_ctrl":{"type":"number"},"reward_survive":{"type":"number"},"reward_contact":{"type":"number"},"learned_reward":{"type":"number"},"terminated":{"type":"boolean"},"truncated":{"type":"boolean"}},"required":["episode","t","obs","action","next_obs","reward","terminated","truncated"]}"#;

/// Per-step learned rewards, one vector per trajectory, where a reward model scored them.
pub type LearnedRewards<'a> = Option<&'a [Vec<f64>]>;

/// Writes `trajs` to `path` (env name and step duration `dt` go into the metadata).
pub fn write(path: &Path, env: &str, dt: f64, trajs: &[Trajectory], learned: LearnedRewards) -> Result<()> {
    let file = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
    write_to(BufWriter::new(file), env, dt, trajs, learned).map_err(|e| Error::file(path, format!("cannot write MCAP: {e}")))?;
    Ok(())
}

fn write_to<W: Write + Seek>(
    w: W,
    env: &str,
    dt: f64,
    trajs: &[Trajectory],
    learned: LearnedRewards,
) -> std::result::Result<(), mcap::McapError> {
    let mut out = mcap::WriteOptions::new().profile("").library(concat!("idrex ", env!("CARGO_PKG_VERSION"))).create(w)?;
    let ep_schema = out.add_schema("idrex.Episode", "jsonschema", EPISODE_SCHEMA.as_bytes())?;
    let contact = env.parse::<crate::env::EnvId>().is_ok_and(|id| id.spec().contact.is_some());
    let step_schema = out.add_schema("idrex.Step", "jsonschema", if contact { STEP_SCHEMA_CONTACT } else { STEP_SCHEMA }.as_bytes())?;
    let ep_chan = out.add_channel(ep_schema, "/episode", "json", &BTreeMap::new())?;
    let step_chan = out.add_channel(step_schema, "/step", "json", &BTreeMap::new())?;
    let dt_ns = (dt * 1e9).round() as u64;
    let (mut clock, mut seq) = (0u64, 0u32);
    let mut index = Vec::new();
    for (e, t) in trajs.iter().enumerate() {
        // Each episode starts one tick after the previous one ended, so time is monotonic.
        clock += dt_ns;
        let start = clock;
        let msg = json!({"episode": e, "source": t.meta.source, "noise": t.meta.noise, "seed": t.meta.seed, "group": t.meta.group, "obs": t.obs_row(0)});
        seq += 1;
        out.write_to_known_channel(
            &mcap::records::MessageHeader { channel_id: ep_chan, sequence: seq, log_time: clock, publish_time: clock },
            msg.to_string().as_bytes(),
        )?;
        for s in 0..t.len() {
            clock += dt_ns;
            seq += 1;
            let last = s + 1 == t.len();
            let terms = t.terms.get(s).copied().unwrap_or_default();
            let mut msg = json!({
                "episode": e, "t": s, "obs": t.obs_row(s), "action": t.action_row(s), "next_obs": t.obs_row(s + 1),
                "reward": t.rewards[s], "reward_forward": terms.reward_forward, "reward_ctrl": terms.reward_ctrl,
                "reward_survive": terms.reward_survive,
                "terminated": last && t.terminated, "truncated": last && t.truncated,
            });
            if contact {
                msg["reward_contact"] = json!(terms.reward_contact);
            }
            // Absent rather than null: Foxglove's JSON-schema parser takes one type per field.
            if let Some(l) = learned {
                msg["learned_reward"] = json!(l[e][s]);
            }
            out.write_to_known_channel(
                &mcap::records::MessageHeader { channel_id: step_chan, sequence: seq, log_time: clock, publish_time: clock },
                msg.to_string().as_bytes(),
            )?;
        }
        index.push(json!({"start_ns": start, "length": t.len(), "return": t.ret(), "noise": t.meta.noise, "source": t.meta.source,
            "seed": t.meta.seed, "group": t.meta.group, "terminated": t.terminated, "truncated": t.truncated}));
    }
    let (od, ad) = trajs.first().map_or((0, 0), |t| (t.obs_dim, t.act_dim));
    let rollout: BTreeMap<String, String> = [
        ("format", FORMAT.to_string()),
        ("env", env.to_string()),
        ("obs_dim", od.to_string()),
        ("act_dim", ad.to_string()),
        ("dt", dt.to_string()),
        ("episodes", trajs.len().to_string()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    out.write_metadata(&mcap::records::Metadata { name: "idrex.rollout".into(), metadata: rollout })?;
    let episodes: BTreeMap<String, String> = index.iter().enumerate().map(|(i, v)| (format!("{i:06}"), v.to_string())).collect();
    out.write_metadata(&mcap::records::Metadata { name: "idrex.episodes".into(), metadata: episodes })?;
    out.finish()?;
    Ok(())
}

/// A rollout file read back.
#[derive(Debug, Clone, Default)]
pub struct Rollouts {
    pub env: String,
    pub dt: f64,
    pub trajectories: Vec<Trajectory>,
    /// Per-step learned rewards, where the file has them.
    pub learned: Option<Vec<Vec<f64>>>,
}

fn corrupt(path: &Path, e: impl std::fmt::Display) -> Error {
    Error::file(path, format!("truncated or corrupt MCAP file ({e}); delete it or re-run the stage that wrote it"))
}

fn nums(v: &serde_json::Value, key: &str) -> Option<Vec<f32>> {
    v.get(key)?.as_array()?.iter().map(|x| x.as_f64().map(|f| f as f32)).collect()
}

pub fn read(path: &Path) -> Result<Rollouts> {
    parse(path, &std::fs::read(path).map_err(|e| Error::io(path, e))?)
}

/// Every message of an MCAP file's bytes, as (topic, sequence, payload), read with a limit on
/// every record's declared length: the crate's message stream trusts a chunk's inner lengths
/// and would allocate whatever a corrupt one claims. Chunk CRCs are checked, since zstd may
/// not notice a flipped byte inside compressed data.
fn messages(buf: &[u8], mut each: impl FnMut(&str, u32, &[u8]) -> Result<()>) -> std::result::Result<Result<()>, String> {
    use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
    // No record of a real file is longer than the file could decompress to.
    let limit = buf.len().saturating_mul(MAX_DECOMPRESSION).min(MAX_RECORD);
    let mut reader =
        LinearReader::new_with_options(LinearReaderOptions::default().with_record_length_limit(limit).with_validate_chunk_crcs(true));
    let mut topics: BTreeMap<u16, String> = BTreeMap::new();
    let mut at = 0;
    while let Some(event) = reader.next_event() {
        match event.map_err(|e| e.to_string())? {
            LinearReadEvent::ReadRequest(n) => {
                let n = n.min(buf.len() - at);
                reader.insert(n).copy_from_slice(&buf[at..at + n]);
                reader.notify_read(n);
                at += n;
            }
            LinearReadEvent::Record { data, opcode } => match mcap::parse_record(opcode, data).map_err(|e| e.to_string())? {
                mcap::records::Record::Channel(c) => {
                    topics.insert(c.id, c.topic);
                }
                mcap::records::Record::Message { header, data } => {
                    let topic = topics.get(&header.channel_id).ok_or(format!("message {} on an undeclared channel", header.sequence))?;
                    if let Err(e) = each(topic, header.sequence, &data) {
                        return Ok(Err(e));
                    }
                }
                _ => {}
            },
        }
    }
    Ok(Ok(()))
}

/// The most a record may claim: per byte of the file, and in all.
const MAX_DECOMPRESSION: usize = 4096;
const MAX_RECORD: usize = 1 << 30;

/// The rollouts in an MCAP file's bytes; `path` names it in every refusal.
pub fn parse(path: &Path, buf: &[u8]) -> Result<Rollouts> {
    // Another kind of file is named as such, not called corrupt (nor offered for deletion).
    if !buf.starts_with(mcap::MAGIC) {
        return Err(Error::file(path, "is not an MCAP file (rollouts are the rollouts.mcap files of a store's artifacts)"));
    }
    // A file cut short has no valid footer; catch that before streaming.
    mcap::read::footer(buf).map_err(|e| corrupt(path, e))?;
    let summary = mcap::read::Summary::read(buf).map_err(|e| corrupt(path, e))?.ok_or_else(|| corrupt(path, "no summary section"))?;
    let mut meta = BTreeMap::new();
    for idx in &summary.metadata_indexes {
        let m = mcap::read::metadata(buf, idx).map_err(|e| corrupt(path, e))?;
        if m.name == "idrex.rollout" {
            meta = m.metadata;
        }
    }
    if meta.get("format").map(String::as_str) != Some(FORMAT) {
        return Err(Error::file(path, format!("not an idrex rollout file (no idrex.rollout metadata with format {FORMAT})")));
    }
    let mut r = Rollouts {
        env: meta.get("env").cloned().unwrap_or_default(),
        dt: meta.get("dt").and_then(|d| d.parse().ok()).unwrap_or(0.0),
        ..Default::default()
    };
    let obs_dim: usize = meta.get("obs_dim").and_then(|d| d.parse().ok()).unwrap_or(0);
    let act_dim: usize = meta.get("act_dim").and_then(|d| d.parse().ok()).unwrap_or(0);
    let mut learned: Vec<Vec<f64>> = Vec::new();
    let mut any_learned = false;
    let outcome = messages(buf, |topic, sequence, data| {
        let v: serde_json::Value = serde_json::from_slice(data).map_err(|e| corrupt(path, e))?;
        let bad = |what: &str| corrupt(path, format!("message {sequence} on {topic} has no valid {what}"));
        match topic {
            "/episode" => {
                let obs = nums(&v, "obs").ok_or_else(|| bad("obs"))?;
                r.trajectories.push(Trajectory {
                    obs_dim,
                    act_dim,
                    obs,
                    meta: TrajMeta {
                        source: v["source"].as_str().unwrap_or_default().to_string(),
                        noise: v["noise"].as_f64().unwrap_or(0.0),
                        seed: v["seed"].as_u64().unwrap_or(0),
                        group: v["group"].as_u64().unwrap_or(0) as usize,
                    },
                    ..Default::default()
                });
                learned.push(Vec::new());
            }
            "/step" => {
                let t = r.trajectories.last_mut().ok_or_else(|| bad("episode (a step before any /episode message)"))?;
                t.obs.extend(nums(&v, "next_obs").ok_or_else(|| bad("next_obs"))?);
                t.actions.extend(nums(&v, "action").ok_or_else(|| bad("action"))?);
                t.rewards.push(v["reward"].as_f64().ok_or_else(|| bad("reward"))?);
                t.terms.push(RewardTerms {
                    reward_forward: v["reward_forward"].as_f64().unwrap_or(0.0),
                    reward_ctrl: v["reward_ctrl"].as_f64().unwrap_or(0.0),
                    reward_survive: v["reward_survive"].as_f64().unwrap_or(0.0),
                    reward_contact: v["reward_contact"].as_f64().unwrap_or(0.0),
                });
                t.terminated = v["terminated"].as_bool().unwrap_or(false);
                t.truncated = v["truncated"].as_bool().unwrap_or(false);
                if let Some(l) = v["learned_reward"].as_f64() {
                    any_learned = true;
                    learned.last_mut().expect("pushed with the episode").push(l);
                }
            }
            _ => {}
        }
        Ok(())
    });
    outcome.map_err(|e| corrupt(path, e))??;
    for t in &r.trajectories {
        if t.obs.len() != (t.len() + 1) * obs_dim || t.actions.len() != t.len() * act_dim {
            return Err(corrupt(path, "an episode's observations or actions do not match the dimensions in its metadata"));
        }
    }
    r.learned = any_learned.then_some(learned);
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn traj(len: usize, noise: f64) -> Trajectory {
        Trajectory {
            obs_dim: 2,
            act_dim: 1,
            obs: (0..=len).flat_map(|t| [t as f32, -(t as f32)]).collect(),
            actions: (0..len).map(|t| t as f32 * 0.1).collect(),
            rewards: (0..len).map(|t| t as f64).collect(),
            terms: vec![RewardTerms { reward_forward: 1.0, reward_ctrl: -0.5, reward_survive: 0.0, reward_contact: 0.0 }; len],
            terminated: true,
            truncated: false,
            meta: TrajMeta { source: "bc".into(), noise, seed: 3, group: 1 },
        }
    }

    #[test]
    fn round_trips_and_rejects_truncated_files() {
        let dir = std::env::temp_dir().join(format!("idrex-mcap-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("r.mcap");
        let trajs = vec![traj(5, 0.0), traj(3, 0.5)];
        write(&path, "Hopper-v5", 0.008, &trajs, None).unwrap();
        let back = read(&path).unwrap();
        assert_eq!(back.env, "Hopper-v5");
        assert_eq!(back.trajectories, trajs);
        assert!(back.learned.is_none());
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
        let err = read(&path).unwrap_err().to_string();
        assert!(err.contains("truncated or corrupt MCAP"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Found by the fuzz tests: a record inside a chunk that claims an absurd length made the
    /// crate's message stream allocate it (and abort) before any CRC was checked.
    #[test]
    fn a_chunk_record_claiming_exabytes_is_refused_not_allocated() {
        let mut buf = Vec::new();
        {
            let opts = mcap::WriteOptions::new().compression(None).profile("");
            let mut w = opts.create(std::io::Cursor::new(&mut buf)).unwrap();
            let chan = w.add_channel(0, "/episode", "json", &BTreeMap::new()).unwrap();
            let header = mcap::records::MessageHeader { channel_id: chan, sequence: 0, log_time: 0, publish_time: 0 };
            w.write_to_known_channel(&header, b"PAYLOAD-MARK").unwrap();
            let rollout = BTreeMap::from([("format".to_string(), FORMAT.to_string())]);
            w.write_metadata(&mcap::records::Metadata { name: "idrex.rollout".into(), metadata: rollout }).unwrap();
            w.finish().unwrap();
        }
        let mark = buf.windows(12).position(|x| x == b"PAYLOAD-MARK").expect("the payload, uncompressed");
        // The message record: opcode, length (u64), channel (u16), sequence (u32), two times (u64).
        let len_at = mark - 22 - 8;
        assert_eq!(buf[len_at - 1], 0x05, "a message record");
        buf[len_at..len_at + 8].copy_from_slice(&(u64::MAX / 5).to_le_bytes());
        let err = parse(Path::new("r.mcap"), &buf).unwrap_err().to_string();
        assert!(err.starts_with("r.mcap: truncated or corrupt MCAP"), "{err}");
    }
}
