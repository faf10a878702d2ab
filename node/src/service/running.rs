//! A node running on its threads, and what can be done to it while it runs.

use super::{
    Arc, Model, NodeService, NodeStats, Path, ServiceError, Shared, Tap, TerrainCatalog, Threaded,
};

/// A node running on its threads (from [`NodeService::start`]).
pub struct RunningNode {
    pub(super) threads: Threaded<NodeService>,
    pub(super) catalog: TerrainCatalog,
    pub(super) shared: Arc<Shared>,
    pub(super) tap: Option<Arc<dyn Tap>>,
}

impl RunningNode {
    /// Loads and checks the model at `path` on the caller's thread, then hands it to the
    /// pipeline, which installs it between two frames; returns its id. A bad file is an error
    /// here and the running model stays.
    pub fn reload_model(&self, path: &Path) -> Result<u64, ServiceError> {
        let model = Model::load(path)?;
        model.check_catalog(&self.catalog)?;
        self.install(model, self.catalog.clone())
    }

    /// [`Self::reload_model`] with the terrains read again (`catalog`, from the node's
    /// terrains file): a terrain added since start (`presrs discover --add`) is reported by
    /// its name. A catalog that drops a terrain the model has is refused with the model.
    pub fn reload(&mut self, path: &Path, catalog: TerrainCatalog) -> Result<u64, ServiceError> {
        let model = Model::load(path)?;
        model.check_catalog(&catalog)?;
        let id = self.install(model, catalog.clone())?;
        self.catalog = catalog;
        Ok(id)
    }

    /// Runs until `signals` say stop or a thread ends, each SIGHUP reloading the model at
    /// `model` with the terrains file `terrains` read again (`presrs discover --add` may have
    /// added one); a file that fails keeps what is loaded, and says so in the log.
    pub fn serve(
        &mut self,
        signals: &protocol::component::Signals,
        model: &Path,
        terrains: Option<&Path>,
    ) {
        while !signals.stopping() && self.is_running() {
            if signals.take_reload() {
                let reloaded = match TerrainCatalog::load(terrains) {
                    Ok(c) => self.reload(model, c),
                    Err(e) => {
                        tracing::error!("SIGHUP: {e}; keeping the terrains read at start");
                        self.reload_model(model)
                    }
                };
                match reloaded {
                    Ok(id) => {
                        tracing::info!(model = %model.display(), model_id = id, "SIGHUP: model reloaded")
                    }
                    Err(e) => tracing::error!("SIGHUP: {e}; keeping the model already loaded"),
                }
            }
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
    }

    fn install(&self, model: Model, catalog: TerrainCatalog) -> Result<u64, ServiceError> {
        let id = model.id();
        let installed = self
            .threads
            .call(move |node| match node.set_model_in(model, catalog) {
                Ok(id) => tracing::info!(
                    model_id = id,
                    "model reloaded; deciding frame {}",
                    node.sample_time()
                ),
                Err(e) => tracing::error!("{e}; keeping the model already loaded"),
            });
        if !installed {
            return Err(ServiceError::Stopped);
        }
        Ok(id)
    }

    /// The terrains the node reports.
    pub fn catalog(&self) -> &TerrainCatalog {
        &self.catalog
    }

    /// The counters now.
    pub fn stats(&self) -> NodeStats {
        NodeStats {
            record_dropped: self.tap.as_ref().map_or(0, |t| t.dropped()),
            ..self.shared.snapshot()
        }
    }

    /// True while every thread runs.
    pub fn is_running(&self) -> bool {
        self.threads.is_running()
    }

    /// Stops the threads (a last NodeStatus says `Stopping`), joins them and returns the final
    /// counters.
    pub fn stop(self) -> NodeStats {
        let node = self.threads.stop();
        let s = NodeStats {
            record_dropped: self.tap.as_ref().map_or(0, |t| t.dropped()),
            ..self.shared.snapshot()
        };
        tracing::info!(
            rx_frames = s.rx_frames,
            rx_dropped = s.rx_dropped,
            tx_frames = s.tx_frames,
            tx_dropped = s.tx_dropped,
            bus_errors = s.bus_errors,
            steps = s.steps,
            classified = s.classified,
            unknown = s.unknown,
            unknown_by_reason = %s.unknown_by_reason,
            unknown_by_gait = %node.as_ref().map(|n| n.describe_gaits()).unwrap_or_default(),
            record_dropped = s.record_dropped,
            "presrs node stopped"
        );
        s
    }
}
