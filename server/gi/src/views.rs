//! Debug views: the images a researcher expects next to the final frame (the seed papers'
//! figures of their intermediate data). Each method declares its views in
//! `gi/<method>/views.rs`, each with what it shows and the code that draws it from the data
//! the method captured for it ([`super::Method::capture_debug`]); its table lists them
//! ([`super::params::MethodTable::views`]). This module finds a view by name and checks that
//! the frame's method draws it; `/v1/server`, the OpenAPI schema, `--view` and the viewer's
//! menu are derived from the tables.

use super::{common::views::Image, precompute::SceneData, DebugData, GiMethod};
use crate::scene::Aabb;
use lightcast_protocol::{Camera, View};

/// One debug view.
#[derive(Debug)]
pub struct DebugView {
    pub name: View,
    /// What the image shows, for people (`/v1/server`).
    pub summary: &'static str,
    /// The view is drawn from the frame's indirect-light buffer, which the frame must then
    /// read back.
    pub reads_indirect: bool,
    /// Draws the view; `None` when the frame lacks what it shows.
    pub draw: fn(&ViewInputs) -> Option<Image>,
}

/// What a view is drawn from: the frame as read back, its camera and scene.
pub struct ViewInputs<'a> {
    pub width: u32,
    pub height: u32,
    /// The final image, sRGB RGBA8.
    pub rgba8: &'a [u8],
    /// Linear indirect radiance (RGBA), when the view [`DebugView::reads_indirect`].
    pub indirect: Option<&'a [[f32; 4]]>,
    /// The exposure scale the frame was tone-mapped with.
    pub exposure_scale: f32,
    /// What the method captured for the view.
    pub debug: Option<&'a DebugData>,
    pub camera: &'a Camera,
    pub bounds: &'a Aabb,
    /// The scene's precomputed data for the method, if it has any.
    pub scene_data: Option<&'a SceneData>,
}

impl ViewInputs<'_> {
    /// The method's capture for the view, as its own type.
    pub fn debug<T: 'static>(&self) -> Option<&T> {
        self.debug.and_then(|d| d.0.downcast_ref::<T>())
    }

    /// The method's precomputed scene data, as its own type.
    pub fn scene_data<T: 'static>(&self) -> Option<&T> {
        self.scene_data.and_then(|d| d.downcast_ref::<T>())
    }
}

/// Why a debug view cannot be shown.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    #[error("unknown view {view}; this server's views are {known}")]
    Unknown { view: View, known: String },
    #[error(
        "view {view} is drawn by GI method {}, not by {method}",
        list(drawn_by)
    )]
    NotDrawn {
        view: View,
        method: GiMethod,
        drawn_by: Vec<GiMethod>,
    },
    #[error("the frame holds no data for view {view}")]
    Missing { view: View },
}

fn list(methods: &[GiMethod]) -> String {
    let names: Vec<&str> = methods.iter().map(GiMethod::name).collect();
    names.join(" or ")
}

/// The methods that draw `view`, in registry order.
pub fn drawn_by(view: View) -> Vec<GiMethod> {
    super::methods()
        .filter(|&m| super::table(m).views.iter().any(|v| v.name == view))
        .collect()
}

/// Every view name: `final`, then each method's in registry order, once each.
pub fn names() -> Vec<View> {
    let mut names = vec![View::FINAL];
    for method in super::methods() {
        for v in super::table(method).views {
            if !names.contains(&v.name) {
                names.push(v.name);
            }
        }
    }
    names
}

/// The view `view` of frames of `method`: `None` for `final`, which every method shows.
pub fn check(view: View, method: GiMethod) -> Result<Option<&'static DebugView>, ViewError> {
    if view == View::FINAL {
        return Ok(None);
    }
    if let Some(v) = super::table(method).views.iter().find(|v| v.name == view) {
        return Ok(Some(v));
    }
    let drawn_by = drawn_by(view);
    if drawn_by.is_empty() {
        return Err(unknown(view));
    }
    Err(ViewError::NotDrawn {
        view,
        method,
        drawn_by,
    })
}

/// A registered view by name, for command-line flags (`--view`).
pub fn parse(name: &str) -> Result<View, String> {
    let view = View::parse(name)?;
    if view == View::FINAL || find(view).is_some() {
        Ok(view)
    } else {
        Err(unknown(view).to_string())
    }
}

/// The refusal of a view no method declares, listing every view.
fn unknown(view: View) -> ViewError {
    let known: Vec<String> = names().iter().map(ToString::to_string).collect();
    ViewError::Unknown {
        view,
        known: known.join(", "),
    }
}

/// The declaration of `view` (`None` for `final` and for names no method declares).
pub fn find(view: View) -> Option<&'static DebugView> {
    super::methods()
        .flat_map(|m| super::table(m).views)
        .find(|v| v.name == view)
        .copied()
}

/// Whether frames shown as `view` read back their indirect light.
pub fn reads_indirect(view: View) -> bool {
    find(view).is_some_and(|v| v.reads_indirect)
}

/// The README's table of debug views, derived from the tables (a test keeps the README's
/// copy; `lightcast-server gi-views` prints it).
pub fn markdown_table() -> String {
    let mut s = String::from("| view | methods | shows |\n|---|---|---|\n");
    s.push_str("| `final` | every method | The tone-mapped frame. |\n");
    for view in names().into_iter().skip(1) {
        let Some(declared) = find(view) else { continue };
        let methods: Vec<String> = drawn_by(view).iter().map(|m| format!("`{m}`")).collect();
        s.push_str(&format!(
            "| `{view}` | {} | {} |\n",
            methods.join(", "),
            declared.summary
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gi::{methods, table};

    /// The README's view table is the tables' (`lightcast-server gi-views` prints it).
    #[test]
    fn the_readme_lists_the_views_of_the_tables() {
        let readme = include_str!("../../../README.md");
        let (begin, end) = ("<!-- gi-views:begin -->\n", "<!-- gi-views:end -->");
        let start = readme.find(begin).expect("the README marks its table") + begin.len();
        let len = readme[start..].find(end).expect("and its end");
        let table = markdown_table();
        assert!(
            readme[start..start + len] == table,
            "the README's view table is stale; replace it with `lightcast-server gi-views`:\n{table}"
        );
    }

    /// A name means one view: two methods listing the same name list the same declaration
    /// (`lightskin` and `brsm` share theirs), and no method lists `final`.
    #[test]
    fn every_view_name_has_one_declaration() {
        let mut seen: Vec<&'static DebugView> = Vec::new();
        for method in methods() {
            for &v in table(method).views {
                assert_ne!(v.name, View::FINAL, "{method} lists final");
                if let Some(other) = seen.iter().find(|o| o.name == v.name) {
                    assert!(std::ptr::eq(*other, v), "view {} is declared twice", v.name);
                }
                seen.push(v);
            }
        }
    }

    /// Every method shows `final`, draws its own views and is refused the others', naming
    /// the methods that draw them.
    #[test]
    fn a_view_is_checked_against_the_frames_method() {
        for method in methods() {
            assert!(check(View::FINAL, method).unwrap().is_none());
            for name in names().into_iter().skip(1) {
                let own = table(method).views.iter().any(|v| v.name == name);
                match check(name, method) {
                    Ok(Some(v)) => assert!(own && v.name == name, "{name} for {method}"),
                    Err(ViewError::NotDrawn { drawn_by: by, .. }) => {
                        assert!(!own && !by.contains(&method), "{name} for {method}");
                        assert_eq!(by, drawn_by(name));
                    }
                    other => panic!("{name} for {method}: {other:?}"),
                }
            }
        }
        let err = check(View::new("nonsense"), GiMethod::default()).unwrap_err();
        assert!(matches!(err, ViewError::Unknown { .. }), "{err}");
        for name in names() {
            assert!(err.to_string().contains(name.name()), "{err}");
        }
        assert!(parse("final").is_ok() && parse("nonsense").is_err() && parse("No").is_err());
        assert!(!reads_indirect(View::FINAL));
    }
}
