//! `/vo/ping`, `/vo/status` and subscriptions (`/vo/subscribe`, `/vo/unsubscribe`).

use std::net::SocketAddr;

use rosc::OscMessage;

use super::{Context, int, opt_int_arg};
use crate::engine::{Outcome, Refusal, SUBSCRIPTIONS_PER_HOST, msg};
use crate::osc::args::Request;

pub enum Cmd {
    Ping(Vec<rosc::OscType>),
    Status,
    Subscribe(Option<u16>),
    Unsubscribe,
}

impl Cmd {
    pub fn parse(req: &Request) -> Result<Option<Cmd>, String> {
        Ok(Some(if req.matches("/vo/ping").is_some() {
            Cmd::Ping(req.args().to_vec())
        } else if req.matches("/vo/status").is_some() {
            Cmd::Status
        } else if req.matches("/vo/subscribe").is_some() {
            let port = opt_int_arg(req, 0, "port", 0, 65535, 0)? as u16;
            Cmd::Subscribe((port != 0).then_some(port))
        } else if req.matches("/vo/unsubscribe").is_some() {
            Cmd::Unsubscribe
        } else {
            return Ok(None);
        }))
    }

    pub fn apply(self, cx: &Context) -> Result<Vec<OscMessage>, Refusal> {
        let e = cx.engine;
        let from = cx.peer.addr().ip();
        match self {
            Cmd::Ping(args) => Ok(vec![msg("/vo/pong", args)]),
            Cmd::Status => cx.commit(|s| Ok(Outcome::reply(e.status(s)))),
            Cmd::Subscribe(port) => {
                let to = SocketAddr::new(from, port.unwrap_or(cx.peer.reply_addr().port()));
                let ended = e.subscribe(from, to);
                // The whole state goes where the pushes will go, so a tablet that
                // listens on another port than it sends from is complete at once.
                let state = cx.commit(|s| {
                    let mut state = Vec::new();
                    if let Some((k, m)) = s.entry {
                        state.push(msg("/vo/picked", vec![int(k), int(m)]));
                    }
                    state.extend(e.feedback(s));
                    state.extend(super::objective::list(s));
                    state.extend(super::looks::list(s));
                    Ok(Outcome::replies(state))
                })?;
                let subscribed = msg("/vo/subscribed", vec![int(to.port().into())]);
                if let Err(err) = e.push_to(to, &state) {
                    e.unsubscribe(from);
                    return Err(Refusal::conflict(format!(
                        "cannot reach {to} to subscribe it: {err}"
                    )));
                }
                let mut replies = vec![subscribed];
                if let Some(old) = ended {
                    replies.push(msg(
                        "/vo/note",
                        vec![rosc::OscType::String(format!(
                            "{from} holds at most {SUBSCRIPTIONS_PER_HOST} subscriptions: the oldest, to {old}, ended for this one"
                        ))],
                    ));
                }
                Ok(replies)
            }
            Cmd::Unsubscribe => {
                e.unsubscribe(from);
                Ok(vec![msg("/vo/unsubscribed", Vec::new())])
            }
        }
    }
}
