//! The vehicle file's and the scenario file's tables as serde reads them, every span kept
//! (checked into [`super::VehicleFile`] by [`super::check`]).

use petrel_nets::manifest::Ordered;
use serde::Deserialize;
use toml::Spanned;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawFile {
    #[serde(default)]
    pub(super) vehicle: RawVehicle,
    #[serde(default)]
    pub(super) computers: Ordered<RawComputer>,
    #[serde(default, rename = "process")]
    pub(super) processes: Vec<RawProcess>,
    #[serde(default, rename = "send")]
    pub(super) sends: Vec<RawSend>,
    pub(super) link: Option<RawLink>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawLink {
    pub(super) detection: Option<Spanned<String>>,
    pub(super) retention: Option<Spanned<String>>,
    pub(super) lost_event: Option<Spanned<String>>,
    pub(super) restored_event: Option<Spanned<String>>,
    pub(super) user: Option<Spanned<String>>,
    pub(super) credentials: Option<Spanned<String>>,
    pub(super) security: Option<Spanned<String>>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(super) struct RawVehicle {
    pub(super) name: Option<Spanned<String>>,
    pub(super) logs: Option<Spanned<String>>,
    pub(super) stop_grace: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawComputer {
    pub(super) address: Option<String>,
    pub(super) description: Option<String>,
    pub(super) gateway: Option<String>,
}

#[derive(Deserialize)]
#[serde(untagged)]
pub(super) enum RawJournal {
    On(bool),
    Path(String),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawProcess {
    pub(super) name: Spanned<String>,
    pub(super) kind: Spanned<String>,
    #[allow(dead_code)]
    pub(super) description: Option<String>,
    pub(super) executable: Option<Spanned<String>>,
    #[serde(default)]
    pub(super) args: Vec<Spanned<String>>,
    #[serde(default)]
    pub(super) env: Ordered<Spanned<String>>,
    pub(super) computer: Option<Spanned<String>>,
    pub(super) wait: Option<Spanned<String>>,
    pub(super) programs: Option<Spanned<Vec<Spanned<String>>>>,
    pub(super) after: Option<Spanned<Vec<Spanned<String>>>>,
    pub(super) restart: Option<Spanned<String>>,
    pub(super) max_restarts: Option<Spanned<i64>>,
    pub(super) backoff: Option<Spanned<String>>,
    pub(super) ready_timeout: Option<Spanned<String>>,
    pub(super) stop_grace: Option<Spanned<String>>,
    pub(super) journal: Option<Spanned<RawJournal>>,
    pub(super) critical: Option<Spanned<bool>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSend {
    pub(super) at: Spanned<String>,
    pub(super) event: Spanned<String>,
    pub(super) computer: Option<Spanned<String>>,
}

/// A scenario file: timed operator events only, to run one vehicle file several ways.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawScenario {
    #[serde(default, rename = "send")]
    pub(super) sends: Vec<RawSend>,
}
