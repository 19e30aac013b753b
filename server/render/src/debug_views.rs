//! A frame's image as its view shows it: the final image, or a debug view its GI method
//! declares (`gi::views`), drawn on the CPU from what the frame read back.

use crate::gi::precompute::SceneData;
use crate::gi::views::ViewInputs;
use crate::renderer::Frame;
use crate::scene::Aabb;
use lightcast_protocol::Camera;

pub use crate::gi::common::views::Image;
pub use crate::gi::views::{check, reads_indirect, ViewError};
pub use lightcast_protocol::View;

/// The image of `view` for `frame`, rendered with `capture_hdr` where the view
/// [`reads_indirect`] and with `debug_view` = `view`; `bounds` are the scene's and
/// `scene_data` its precomputed data for the frame's method. The view was checked against
/// the method ([`check`]) when the frame was asked for.
pub fn compose(
    view: View,
    frame: Frame,
    camera: &Camera,
    bounds: &Aabb,
    scene_data: Option<&SceneData>,
) -> Result<Image, ViewError> {
    if view == View::FINAL {
        return Ok(Image {
            width: frame.width,
            height: frame.height,
            rgba8: frame.rgba8,
        });
    }
    let declared = crate::gi::views::find(view).ok_or(ViewError::Missing { view })?;
    let inputs = ViewInputs {
        width: frame.width,
        height: frame.height,
        rgba8: &frame.rgba8,
        indirect: frame.indirect.as_deref(),
        exposure_scale: frame.exposure_scale,
        debug: frame.debug.as_ref(),
        camera,
        bounds,
        scene_data,
    };
    (declared.draw)(&inputs).ok_or(ViewError::Missing { view })
}
