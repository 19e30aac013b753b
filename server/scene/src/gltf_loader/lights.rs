//! Cameras and `KHR_lights_punctual` lights of the nodes that carry them.

use super::*;

impl Loader<'_> {
    pub(super) fn add_camera(&mut self, index: usize, world: &Mat4) -> Result<(), LoadError> {
        let Some(camera) = self.root.cameras.get(index) else {
            return Err(invalid(format!("camera {index}"), "does not exist"));
        };
        let part = named("camera", index, camera.name.as_deref());
        match camera.type_ {
            Checked::Valid(CameraType::Perspective) => {
                let Some(perspective) = &camera.perspective else {
                    return Err(invalid(
                        part,
                        "is perspective but has no perspective object",
                    ));
                };
                let yfov = perspective.yfov;
                if !(yfov > 0.0 && yfov < std::f32::consts::PI) {
                    return Err(invalid(
                        part,
                        format!("yfov {yfov} is not between 0 and π radians"),
                    ));
                }
                let position = world.transform_point3(Vec3::ZERO);
                let forward = world
                    .transform_vector3(Vec3::NEG_Z)
                    .try_normalize()
                    .ok_or_else(|| invalid(&part, "node transform collapses the view direction"))?;
                // A valid file may ask for a field of view the renderer refuses; the camera is
                // still the file's intended view, so it is kept within the renderer's range.
                let fov_y_degrees = yfov.to_degrees().clamp(1.0, 179.0);
                if fov_y_degrees != yfov.to_degrees() {
                    tracing::warn!(
                        "{part}: yfov of {}° is outside 1°–179°; using {fov_y_degrees}°",
                        yfov.to_degrees()
                    );
                }
                self.cameras.push(Camera {
                    position: position.to_array(),
                    target: (position + forward).to_array(),
                    fov_y_degrees,
                });
            }
            Checked::Valid(CameraType::Orthographic) => {
                tracing::warn!("{part}: orthographic cameras are not supported; skipped");
            }
            Checked::Invalid => return Err(invalid(part, "type is invalid")),
        }
        Ok(())
    }

    pub(super) fn add_light(
        &mut self,
        index: usize,
        world: &Mat4,
        node_part: &str,
    ) -> Result<(), LoadError> {
        let lights = self
            .root
            .extensions
            .as_ref()
            .and_then(|e| e.khr_lights_punctual.as_ref())
            .map_or(&[][..], |l| l.lights.as_slice());
        let Some(light) = lights.get(index) else {
            return Err(invalid(
                node_part,
                format!(
                    "refers to light {index}, but the file defines {} lights",
                    lights.len()
                ),
            ));
        };
        let part = named("light", index, light.name.as_deref());
        let kind = match light.type_ {
            Checked::Valid(LightType::Directional) => LightKind::Directional,
            Checked::Valid(LightType::Point) => LightKind::Point,
            Checked::Valid(LightType::Spot) => LightKind::Spot,
            Checked::Invalid => return Err(invalid(part, "type is invalid")),
        };
        let (inner_cone, outer_cone) = light
            .spot
            .as_ref()
            .map_or((0.0, std::f32::consts::FRAC_PI_4), |s| {
                (s.inner_cone_angle, s.outer_cone_angle)
            });
        let parameters = light
            .color
            .iter()
            .chain([&light.intensity, &inner_cone, &outer_cone]);
        if !parameters.into_iter().all(|p| p.is_finite()) {
            return Err(invalid(part, "has a non-finite parameter"));
        }
        // KHR_lights_punctual's own ranges, which the renderer relies on too.
        if light.color.iter().any(|&c| c < 0.0) || light.intensity < 0.0 {
            return Err(invalid(part, "color and intensity must not be negative"));
        }
        if !(0.0 <= inner_cone
            && inner_cone <= outer_cone
            && outer_cone <= std::f32::consts::FRAC_PI_2)
        {
            return Err(invalid(
                part,
                format!(
                    "spot cone angles need 0 ≤ innerConeAngle ≤ outerConeAngle ≤ π/2, got \
                     {inner_cone} and {outer_cone}"
                ),
            ));
        }
        let direction = world
            .transform_vector3(Vec3::NEG_Z)
            .try_normalize()
            .unwrap_or(Vec3::NEG_Z);
        self.lights.push(Light {
            kind,
            position: world.transform_point3(Vec3::ZERO).to_array(),
            direction: direction.to_array(),
            color: light.color,
            intensity: light.intensity,
            inner_cone,
            outer_cone,
        });
        Ok(())
    }
}
