//! Bodies of the HTTP API (`/v1/scenes`, `/v1/sessions`, `/v1/render`) and its error format.
//!
//! Every field has a default, so `{}` is a valid request. The types accept fields they do not
//! know, so a client keeps reading the answers of a newer server; the server itself refuses
//! unknown fields in requests, so a misspelt parameter is an error that names it rather than a
//! silently ignored value.

use crate::{Camera, Environment, GiMethod, Light, View};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use utoipa::ToSchema;

mod gi;
mod render;
mod scenes;
mod server;
mod session;

pub use gi::*;
pub use render::*;
pub use scenes::*;
pub use server::*;
pub use session::*;

/// The id of the scene the server loads at start (the built-in Cornell box).
pub const DEFAULT_SCENE_ID: &str = "default";

/// Every error the API returns, with a 4xx or 5xx status.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ErrorBody {
    /// Stable machine-readable kind, e.g. `invalid_field`, `not_found`, `unauthorized`.
    pub error: String,
    /// The request field at fault, as a path (`render.gi.rsm_size`), when one is.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
    /// What went wrong, for people.
    pub message: String,
}
