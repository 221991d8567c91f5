//! `/vo/generate`, its settings, and `/vo/explore` (galleries that follow a dragged
//! region, src/engine/explore.rs).

use rosc::OscMessage;

use std::ops::RangeInclusive;

use super::{Context, int, int_arg, switch_arg};
use crate::engine::session::{CLUSTERS, COUNT, SEED};
use crate::engine::{Outcome, Refusal, msg};
use crate::osc::args::Request;
use visobjd_method::gallery::MAX_SEED;

pub enum Cmd {
    /// Starts a generate; the reply, `/vo/generated`, goes to the peer when it is done.
    Generate,
    /// Generates once with this seed, leaving the seed setting alone (what a main sends
    /// its backups, so their galleries are the main's).
    Seeded(u64),
    /// `/vo/explore 1|0`: galleries follow the region updates until explore is off.
    Explore(bool),
    Set(GenerateSetting),
}

/// A generation setting, kept in the session.
pub enum GenerateSetting {
    Count(u32),
    Clusters(u32),
    Seed(u64),
}

impl Cmd {
    pub fn parse(req: &Request) -> Result<Option<Cmd>, String> {
        Ok(Some(if req.matches("/vo/generate").is_some() {
            Cmd::Generate
        } else if req.matches("/vo/generate/seeded").is_some() {
            Cmd::Seeded(int_arg(req, 0, "seed", 1, MAX_SEED as i64)? as u64)
        } else if req.matches("/vo/explore").is_some() {
            Cmd::Explore(switch_arg(req, "explore")?)
        } else if req.matches("/vo/generate/count").is_some() {
            Cmd::Set(GenerateSetting::Count(setting(req, "count", &COUNT)?))
        } else if req.matches("/vo/generate/clusters").is_some() {
            Cmd::Set(GenerateSetting::Clusters(setting(
                req, "clusters", &CLUSTERS,
            )?))
        } else if req.matches("/vo/generate/seed").is_some() {
            Cmd::Set(GenerateSetting::Seed(setting(req, "seed", &SEED)?))
        } else {
            return Ok(None);
        }))
    }

    pub fn apply(self, cx: &Context) -> Result<Vec<OscMessage>, Refusal> {
        let e = cx.engine;
        let setting = match self {
            Cmd::Generate => {
                e.generate(None, cx.later())?;
                return Ok(Vec::new());
            }
            Cmd::Seeded(seed) => {
                e.generate(Some(seed), cx.later())?;
                return Ok(Vec::new());
            }
            Cmd::Explore(on) => {
                let reply = if on {
                    let seed = e.explore_start()?;
                    msg("/vo/explore", vec![int(1), int(seed as usize)])
                } else {
                    let (galleries, seed) = e.explore_stop()?;
                    msg(
                        "/vo/explore",
                        vec![int(0), int(galleries as usize), int(seed as usize)],
                    )
                };
                // Other tablets learn that the gallery follows someone's hand (or stopped).
                e.notify(std::slice::from_ref(&reply));
                return Ok(vec![reply]);
            }
            Cmd::Set(setting) => setting,
        };
        cx.commit(|s| {
            let reply = match setting {
                GenerateSetting::Count(n) => {
                    s.count = n;
                    msg("/vo/generate/count", vec![int(n as usize)])
                }
                GenerateSetting::Clusters(c) => {
                    s.clusters = c;
                    msg("/vo/generate/clusters", vec![int(c as usize)])
                }
                GenerateSetting::Seed(seed) => {
                    s.seed = seed;
                    msg("/vo/generate/seed", vec![int(seed as usize)])
                }
            };
            Ok(Outcome::reply(reply).saved())
        })
    }
}

/// Argument 0 as a setting in `range` (the range `session.json` is restored within).
fn setting<T>(req: &Request, what: &str, range: &RangeInclusive<T>) -> Result<T, String>
where
    T: Copy + Into<u64> + TryFrom<i64>,
{
    let bound = |v: T| i64::try_from(v.into()).unwrap_or(i64::MAX);
    let v = int_arg(req, 0, what, bound(*range.start()), bound(*range.end()))?;
    T::try_from(v).map_err(|_| format!("{what} {v} is out of range"))
}
