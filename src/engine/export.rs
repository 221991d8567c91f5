//! `/vo/eos/preset`: the live look recorded on an Eos console as a preset, on a thread of
//! its own (an Eos console may be slow to connect), through `crate::eos`'s commands.

use rosc::OscType;

use super::{Engine, Later, Refusal, msg};

impl Engine {
    /// Pushes the live look to the configured Eos console and records it as preset `n`; the
    /// answer (`/vo/eos/preset n lights`, or why it could not be sent) goes to `answer`.
    pub fn eos_preset(&self, n: u32, answer: Later) -> Result<(), Refusal> {
        let config = self.config().eos.clone();
        let to = config.target().map_err(Refusal::conflict)?.ok_or_else(|| {
            Refusal::conflict(
                "no Eos console is configured: set [eos] address (and protocol) in the config",
            )
        })?;
        let stage = self.stage();
        let commands = crate::eos::preset_commands(&stage.scene, &self.session().live, n);
        let lights = stage.scene.lights.len();
        self.threads
            .spawn("eos", move || {
                answer(match crate::eos::push(&config, to, &commands) {
                    Ok(()) => Ok(vec![msg(
                        "/vo/eos/preset",
                        vec![OscType::Int(n as i32), OscType::Int(lights as i32)],
                    )]),
                    Err(e) => {
                        tracing::warn!("/vo/eos/preset {n}: {e}");
                        Err(Refusal::internal(e))
                    }
                });
            })
            .map_err(|e| Refusal::internal(format!("cannot start the Eos export: {e}")))
    }
}
