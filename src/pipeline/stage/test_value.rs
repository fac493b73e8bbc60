//! `test-value`, for the engine's own tests only (never in a pipeline file): writes its
//! `value` plus its inputs' values to value.txt, optionally after a sleep or failing.
use super::StageCtx;
use crate::error::{Error, Result};

#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    pub value: i64,
    #[serde(default)]
    pub sleep_ms: u64,
    #[serde(default)]
    pub fail: bool,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Metrics {
    pub value: i64,
}

pub fn run(p: &Params, ctx: &StageCtx) -> Result<Metrics> {
    std::thread::sleep(std::time::Duration::from_millis(p.sleep_ms));
    if p.fail {
        return Err(Error::Invalid("this test stage was asked to fail".into()));
    }
    let mut v = p.value;
    for dir in ctx.inputs.values() {
        let path = dir.join("value.txt");
        let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
        v += text.trim().parse::<i64>().map_err(|e| Error::file(&path, e.to_string()))?;
    }
    std::fs::write(ctx.out.join("value.txt"), v.to_string()).map_err(|e| Error::io(ctx.out, e))?;
    Ok(Metrics { value: v })
}
