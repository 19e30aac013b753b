//! The GI methods as `/v1/server` describes them, and `render.gi`: a method's name plus its
//! parameters, which the server's tables own.

use super::*;

/// The type of a GI parameter, for clients that build their controls from `/v1/server`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum GiParamKind {
    Integer,
    Number,
    Boolean,
    /// A number or `null` (the default named in the description).
    OptionalNumber,
    /// One of the strings in `choices`.
    Choice,
}

/// One parameter of a GI method: a field of `render.gi`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct GiParamInfo {
    /// The field name in `render.gi`.
    pub name: String,
    pub kind: GiParamKind,
    /// Default value: a number, boolean or string (a `choice`), or `null` for an optional
    /// number left unset.
    pub default: serde_json::Value,
    /// Smallest accepted value (numbers).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min: Option<f64>,
    /// Largest accepted value on this server (numbers).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max: Option<f64>,
    /// `min` itself is refused (the range is open there).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub min_exclusive: bool,
    /// `max` itself is refused (the range is open there).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub max_exclusive: bool,
    /// The accepted values of a `choice`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub choices: Vec<String>,
    /// The unit of a number (`texels`, `scene units`), when it has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
    pub description: String,
}

/// A GI method as `/v1/server` describes it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct GiMethodInfo {
    pub method: GiMethod,
    /// One line for people, naming the paper and equations.
    pub summary: String,
    /// Whether frames refine while nothing changes (the frame header carries the samples).
    pub progressive: bool,
    /// The fields of `render.gi` this method reads; the others are accepted and ignored.
    pub parameters: Vec<GiParamInfo>,
    /// The debug views the method draws, besides `final` (which every method shows).
    #[serde(default)]
    pub views: Vec<ViewInfo>,
}

/// A debug view as `/v1/server` describes it (`render.view`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ViewInfo {
    pub view: View,
    /// What the image shows, for people.
    pub summary: String,
}

/// Parameters of the GI methods, tagged by `method`: every other field is a parameter one or
/// more methods read, named and bounded by their tables (`/v1/server`'s `gi_methods` lists
/// each method's, with its default, range and unit), so switching methods keeps every other
/// method's settings. The protocol names no method's parameters: the server's methods own
/// them, checks every field against them and fills the ones a request leaves out.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GiParams {
    #[serde(default)]
    pub method: GiMethod,
    /// The parameters by name (`rsm_size`), as JSON values.
    #[serde(flatten)]
    pub values: BTreeMap<String, serde_json::Value>,
}

impl GiParams {
    /// `method` with every parameter at its default.
    pub fn new(method: GiMethod) -> Self {
        Self {
            method,
            values: BTreeMap::new(),
        }
    }

    /// With parameter `name` set to `value`.
    pub fn with(mut self, name: &str, value: impl Into<serde_json::Value>) -> Self {
        self.set(name, value);
        self
    }

    /// Sets parameter `name` to `value`.
    pub fn set(&mut self, name: &str, value: impl Into<serde_json::Value>) {
        self.values.insert(name.to_string(), value.into());
    }

    /// The value of parameter `name` if the parameters name it.
    pub fn get(&self, name: &str) -> Option<&serde_json::Value> {
        self.values.get(name)
    }
}

impl utoipa::PartialSchema for GiParams {
    /// `method` and any parameters; the server's `openapi` command adds every registered
    /// parameter with its bounds to this schema.
    fn schema() -> utoipa::openapi::RefOr<utoipa::openapi::schema::Schema> {
        use utoipa::openapi::schema::{AdditionalProperties, ObjectBuilder};
        ObjectBuilder::new()
            .property(
                "method",
                utoipa::openapi::Ref::from_schema_name(<GiMethod as ToSchema>::name()),
            )
            .additional_properties(Some(AdditionalProperties::FreeForm(true)))
            .description(Some(
                "Parameters of the GI methods, tagged by `method`; every other field is a \
                 parameter of one or more methods (see `/v1/server`'s `gi_methods`).",
            ))
            .into()
    }
}

impl ToSchema for GiParams {
    fn name() -> std::borrow::Cow<'static, str> {
        "GiParams".into()
    }
}

/// How a method's indirect light leaves the surfaces its lights reach directly (the senders:
/// the RSM's texels, VPLs, VALs, surfels).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Senders {
    /// By the whole BRDF: diffuse and glossy reflection, as the truth.
    #[default]
    Full,
    /// By the diffuse lobe alone: the papers' VALs, VPLs and surfels, so every glossy
    /// reflection of a light is missing.
    Diffuse,
}

impl Senders {
    /// The names of the reference's `senders` parameter, in this order.
    pub const NAMES: &'static [&'static str] = &["full", "diffuse"];

    pub const fn name(self) -> &'static str {
        match self {
            Self::Full => "full",
            Self::Diffuse => "diffuse",
        }
    }
}
