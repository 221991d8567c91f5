//! `/vo/generate` and its settings.

use std::sync::Arc;

use rosc::OscMessage;

use super::{int, int_arg};
use crate::engine::{Engine, msg};
use crate::osc::Peer;
use crate::osc::args::Request;

pub enum Cmd {
    Generate,
    Count(u32),
    Clusters(u32),
    Seed(u64),
}

impl Cmd {
    pub fn parse(req: &Request) -> Result<Option<Cmd>, String> {
        Ok(Some(if req.matches("/vo/generate").is_some() {
            Cmd::Generate
        } else if req.matches("/vo/generate/count").is_some() {
            Cmd::Count(int_arg(req, 0, "count", 1, 1000)? as u32)
        } else if req.matches("/vo/generate/clusters").is_some() {
            Cmd::Clusters(int_arg(req, 0, "clusters", 1, 64)? as u32)
        } else if req.matches("/vo/generate/seed").is_some() {
            Cmd::Seed(int_arg(req, 0, "seed", 0, i64::from(i32::MAX))? as u64)
        } else {
            return Ok(None);
        }))
    }

    pub fn apply(self, e: &Arc<Engine>, peer: &Peer) -> Result<Vec<OscMessage>, String> {
        let mut s = e.session();
        let reply = match self {
            Cmd::Generate => {
                drop(s);
                // The reply, /vo/generated, goes to the peer when the work is done.
                e.generate(peer)?;
                return Ok(Vec::new());
            }
            Cmd::Count(n) => {
                s.count = n;
                msg("/vo/generate/count", vec![int(n as usize)])
            }
            Cmd::Clusters(c) => {
                s.clusters = c;
                msg("/vo/generate/clusters", vec![int(c as usize)])
            }
            Cmd::Seed(seed) => {
                s.seed = seed;
                msg("/vo/generate/seed", vec![int(seed as usize)])
            }
        };
        e.persist(s, true)?;
        Ok(vec![reply])
    }
}
