//! `visobjd run`: the daemon.
//!
//! Start-up order keeps the stage lit and a second instance harmless: the state folder is
//! locked and every socket (OSC, web, sACN input) bound first, so a `visobjd run` started
//! by hand beside the service stops before it sends a frame; then the scene description
//! (fast) and the saved live look, which the DMX output starts sending at once, before the
//! basis images are read; only then does OSC answer. sACN receivers hold a source for
//! 2.5 s, so a restart never drops the stage. A `SIGHUP` during all this reloads once the
//! daemon answers.

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::Context;

use crate::cmd::Runner;
use crate::config::Config;
use crate::engine::persist::{Files, restore_live};
use crate::engine::session::Session;
use crate::engine::{Engine, Loaded, keep_scene, stock_references};
use crate::http::Http;
use crate::osc::server::Listeners;
use crate::osc::{Limits, Server};
use visobjd_dmx::Patch;
use visobjd_dmx::{Input, Output};
use visobjd_files::FolderLock;
use visobjd_scene::Scene;
use visobjd_scene::look::Look;

/// Arguments of `run`.
#[derive(clap::Args)]
pub struct Args {
    /// The config file.
    #[arg(long, default_value = "config/visobjd.toml")]
    config: PathBuf,
    /// Log filter when RUST_LOG is not set (error, warn, info, debug, trace).
    #[arg(long, default_value = "info")]
    pub log_level: String,
}

/// Runs the daemon until SIGINT or SIGTERM.
pub fn run(args: Args) -> anyhow::Result<()> {
    super::start_compute_pool();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("cannot start the async runtime")?;
    // SIGHUP is watched from the first moment: one sent while the scene loads (its default
    // action ends the process) is kept and reloads once the daemon answers.
    let hangup = {
        let _inside = runtime.enter();
        tokio::signal::unix::signal(tokio::signal::unix::SignalKind::hangup())
            .context("cannot watch SIGHUP")?
    };

    let config = Config::load(&args.config).map_err(anyhow::Error::msg)?;
    std::fs::create_dir_all(&config.state_dir)
        .with_context(|| format!("state_dir {}: cannot create it", config.state_dir.display()))?;
    // Nothing goes on the wire before the folder is ours and every socket is bound.
    let _lock = FolderLock::take(&config.state_dir).map_err(anyhow::Error::msg)?;
    let osc = Listeners::bind(&config.osc).map_err(anyhow::Error::msg)?;
    let web = (!config.http.listen.is_empty())
        .then(|| Http::bind(&config.http.listen))
        .transpose()
        .map_err(anyhow::Error::msg)?;
    let input_socket = config
        .input
        .sacn
        .as_ref()
        .map(Input::open)
        .transpose()
        .map_err(|e| anyhow::anyhow!("{}: {e}", config.path.display()))?;

    // The patch: the scene's description, or, when it is broken, the one that loaded last
    // (so the saved look stays on the wire while someone fixes it).
    let (scene, stand_in) = match Scene::load(&config.scene) {
        Ok(scene) => (scene, None),
        Err(e) => {
            let why = e.to_string();
            let Some(stand_in) = Loaded::last_scene(&config.scene, &config.state_dir, &why) else {
                anyhow::bail!(
                    "{why} (no scene has loaded from this state folder before, so there is no \
                     patch to keep the stage on)"
                );
            };
            (stand_in.stage.scene.clone(), Some(stand_in))
        }
    };

    // The stage first: the saved live look goes out before anything slow happens.
    let files = Files::new(&config.state_dir);
    let live = restore_live(&files, &scene);
    let initial = live
        .as_ref()
        .map_or_else(|| Look::off(scene.lights.len()), |l| l.live.clone());
    let output = Output::start(
        &config.output,
        Patch::new(&scene),
        &config.state_dir,
        initial,
    )?;
    if let Some(l) = &live {
        output.set_master(l.master);
        output.set_blackout(l.blackout);
    }
    tracing::info!(
        "DMX output running: {} universes, {} sACN and {} Art-Net destinations",
        Patch::new(&scene).universes().len(),
        config.output.sacn.len(),
        config.output.artnet.len()
    );

    // The console's input ignores the output's own CID (its packets may loop back).
    let input = config
        .input
        .sacn
        .as_ref()
        .zip(input_socket)
        .map(|(c, socket)| {
            let allow = config.input_allow_list();
            let permits = Box::new(move |ip| crate::config::permits(&allow, ip));
            Input::start(c, socket, output.cid(), permits)
        })
        .transpose()
        .map_err(|e| anyhow::anyhow!("{}: {e}", config.path.display()))?;

    stock_references(&config);
    let started = std::time::Instant::now();
    let session = Session::new(
        &scene,
        config.generate.count,
        config.generate.clusters,
        config.output.fade_s,
    );
    let loaded = stand_in.unwrap_or_else(|| Loaded::from_scene(scene));
    if loaded.problem.is_none() {
        keep_scene(&config);
        let stage = &loaded.stage;
        tracing::info!(
            "scene `{}` loaded: {} lights at {}x{} in {:.1} s",
            stage.scene.name,
            stage.scene.lights.len(),
            stage.thumbs.width,
            stage.thumbs.height,
            started.elapsed().as_secs_f32()
        );
    }
    let engine = Arc::new(Engine::new(config.clone(), loaded, output, input, session)?);

    let result = runtime.block_on(serve(&config, &engine, osc, web, hangup));
    crate::shutdown::finish(&engine);
    result
}

/// Pings systemd's watchdog at half its period, but only while the DMX clock has ticked
/// since the last ping: a stalled or dead clock (a dark stage) and a wedged runtime (OSC
/// gone) both stop the pings, and systemd restarts the daemon.
async fn watchdog(engine: Arc<Engine>, period: std::time::Duration) {
    let mut tick = tokio::time::interval(period / 2);
    let mut last = None;
    loop {
        tick.tick().await;
        let ticks = engine.output_stats().map(|s| s.ticks);
        if ticks.is_some() && ticks != last {
            let _ = sd_notify::notify(&[sd_notify::NotifyState::Watchdog]);
        } else if ticks.is_some() {
            tracing::error!(
                "the DMX clock has not ticked for {:?}: no watchdog ping",
                period / 2
            );
        }
        last = ticks;
    }
}

/// `SIGHUP` (what `systemctl reload` sends): [`Engine::reload`], off the async threads.
async fn reload_on_hangup(engine: Arc<Engine>, mut hangup: tokio::signal::unix::Signal) {
    while hangup.recv().await.is_some() {
        let engine = Arc::clone(&engine);
        // The reload logs (and tells systemd) its outcome itself.
        let _ = tokio::task::spawn_blocking(move || engine.reload()).await;
    }
}

/// How often a scene that did not load (or left lights out) is looked at again.
const RETRY_SCENE: std::time::Duration = std::time::Duration::from_secs(2);

/// Loads a scene that did not load once its files change ([`Engine::retry_scene`]).
async fn retry_scene(engine: Arc<Engine>) {
    let mut tick = tokio::time::interval(RETRY_SCENE);
    loop {
        tick.tick().await;
        let engine = Arc::clone(&engine);
        let _ = tokio::task::spawn_blocking(move || engine.retry_scene()).await;
    }
}

/// Applies each reloaded config's `[osc]` allow-list and peers to the OSC server.
async fn follow_config(
    mut changes: tokio::sync::watch::Receiver<Arc<Config>>,
    rules: crate::osc::server::Rules,
) {
    while changes.changed().await.is_ok() {
        let config = Arc::clone(&changes.borrow_and_update());
        if let Err(e) = rules.set(&config.osc) {
            tracing::error!("the OSC allow-list and peers were not reloaded: {e}");
        }
    }
}

async fn serve(
    config: &Config,
    engine: &Arc<Engine>,
    osc: Listeners,
    web: Option<std::net::TcpListener>,
    hangup: tokio::signal::unix::Signal,
) -> anyhow::Result<()> {
    let runner = Runner::new(Arc::clone(engine));
    let server = Server::serve(osc, Arc::new(runner.clone()), Limits::default())
        .map_err(anyhow::Error::msg)?;
    if let Some(sender) = server.sender() {
        engine.set_pusher(sender);
    }
    let http = if let Some(listener) = web {
        let http = Http::start(listener, Arc::clone(engine), runner.clone())
            .map_err(anyhow::Error::msg)?;
        tracing::info!("web gallery on http://{}/", http.addr());
        Some(http)
    } else {
        None
    };
    let _ = sd_notify::notify(&[sd_notify::NotifyState::Ready]);
    let mut tasks = Vec::new();
    if let Some(changes) = engine.console_changes() {
        tasks.push(tokio::spawn(Arc::clone(engine).follow_console(changes)));
    }
    if let Some(backup) = &config.backup {
        tracing::info!(
            "backup of {}: sACN at priority {}, commands only from the main",
            backup.main,
            config
                .output
                .sacn
                .iter()
                .map(|d| d.priority.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
        tasks.push(tokio::spawn(crate::backup::follow_main(
            runner.clone(),
            backup.main.trim().to_string(),
        )));
    }
    if let Some(period) = sd_notify::watchdog_enabled() {
        tasks.push(tokio::spawn(watchdog(Arc::clone(engine), period)));
    }
    tasks.push(tokio::spawn(reload_on_hangup(Arc::clone(engine), hangup)));
    tasks.push(tokio::spawn(retry_scene(Arc::clone(engine))));
    tasks.push(tokio::spawn(follow_config(
        engine.config_changes(),
        server.rules(),
    )));
    let signalled = crate::shutdown::signalled().await;
    crate::shutdown::stop_intake(server, http, tasks).await;
    signalled
}
