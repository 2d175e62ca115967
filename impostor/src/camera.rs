//! A pinhole camera: where every pixel's rays start and which way they go.

use glam::Vec3;

/// A perspective camera with square pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// The eye.
    pub eye: Vec3,
    /// Unit view direction.
    pub forward: Vec3,
    /// Unit right vector.
    pub right: Vec3,
    /// Unit up vector.
    pub up: Vec3,
    /// Vertical field of view, radians.
    pub fov_y: f32,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
}

impl Camera {
    /// A camera at `eye` looking at `target`, with +Y up (straight up or down falls back to
    /// +Z as the up hint). `fov_y_degrees` is the vertical field of view.
    pub fn look_at(eye: Vec3, target: Vec3, width: u32, height: u32, fov_y_degrees: f32) -> Self {
        let forward = (target - eye).try_normalize().unwrap_or(Vec3::NEG_Z);
        let hint = if forward.cross(Vec3::Y).length_squared() < 1e-8 {
            Vec3::Z
        } else {
            Vec3::Y
        };
        let right = forward.cross(hint).normalize();
        let up = right.cross(forward);
        Self {
            eye,
            forward,
            right,
            up,
            fov_y: fov_y_degrees.to_radians(),
            width: width.max(1),
            height: height.max(1),
        }
    }

    /// The unit direction through image point (`x`, `y`) in pixels from the top left corner
    /// (pixel centres at half-integers).
    pub fn direction(&self, x: f32, y: f32) -> Vec3 {
        let half = (self.fov_y * 0.5).tan();
        let aspect = self.width as f32 / self.height as f32;
        let sx = (2.0 * x / self.width as f32 - 1.0) * half * aspect;
        let sy = (1.0 - 2.0 * y / self.height as f32) * half;
        (self.forward + sx * self.right + sy * self.up).normalize()
    }

    /// The angle one pixel spans at the image centre, radians.
    pub fn pixel_angle(&self) -> f32 {
        2.0 * (self.fov_y * 0.5).tan() / self.height as f32
    }

    /// Checks that the camera can render: a finite eye, unit orthogonal axes, a field of
    /// view in (0, pi).
    pub fn validate(&self) -> Result<(), String> {
        if !self.eye.is_finite() {
            return Err(format!("camera eye {} is not finite", self.eye));
        }
        for (name, v) in [
            ("forward", self.forward),
            ("right", self.right),
            ("up", self.up),
        ] {
            if !v.is_finite() || (v.length() - 1.0).abs() > 1e-3 {
                return Err(format!("camera {name} {v} is not a unit vector"));
            }
        }
        if self.forward.dot(self.right).abs() > 1e-3 || self.forward.dot(self.up).abs() > 1e-3 {
            return Err("camera axes are not orthogonal".into());
        }
        if !(self.fov_y > 0.0 && self.fov_y < std::f32::consts::PI) {
            return Err(format!(
                "field of view {} rad is not in (0, pi)",
                self.fov_y
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_centre_ray_is_the_view_direction_and_corners_span_the_field_of_view() {
        let cam = Camera::look_at(Vec3::ZERO, Vec3::new(0.0, 0.0, -10.0), 200, 100, 60.0);
        cam.validate().expect("a valid camera");
        assert!(cam.direction(100.0, 50.0).distance(Vec3::NEG_Z) < 1e-6);
        let top = cam.direction(100.0, 0.0);
        let angle = top.angle_between(Vec3::NEG_Z).to_degrees();
        assert!((angle - 30.0).abs() < 1e-3, "{angle}");
        assert!(top.y > 0.0);
        assert!(cam.direction(0.0, 50.0).x < 0.0);
    }

    #[test]
    fn looking_straight_down_still_gives_a_valid_camera() {
        let cam = Camera::look_at(Vec3::new(0.0, 100.0, 0.0), Vec3::ZERO, 64, 64, 45.0);
        cam.validate().expect("a valid camera");
        assert!(cam.forward.distance(Vec3::NEG_Y) < 1e-6);
    }
}
