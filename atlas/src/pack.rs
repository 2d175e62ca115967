//! Stage 2: scale and pack. The placement is a crate's; this file chooses the global texel
//! scale, the packer and the square, and checks what the packer returned with
//! [`Layout::validate`] (see Jylänki, "A thousand ways to pack the bin"):
//! - up to [`MAXRECTS_MAX_CHARTS`] charts, `crunch` (maximal rectangles, largest items first,
//!   best-area fit), the tighter of the two at those counts;
//! - beyond, `guillotiere` (a guillotine allocator, items offered largest area first).
//!   Maximal rectangles costs O(n^2) per packing and a layout takes a dozen packings, which at
//!   thousands of charts would be seconds per atlas.

use glam::DVec2;

use crate::chart::Chart;
use crate::error::AtlasError;
use crate::layout::{Layout, PackedRect};

/// Largest atlas side the packer is asked for: the common GPU texture limit.
const PACKER_MAX_SIDE: u32 = 16384;

/// Most charts packed by maximal rectangles. Measured on 512 x 512 with random chart sizes
/// (the texel scale that packs, bisected, and the time of one packing): at 200 charts maximal
/// rectangles fills 90% of the square against the guillotine's 87%, in 1.9 ms against under
/// 0.1; at 1,000, 91% against 93% in 49 ms against 0.7; at 3,000, 92% against 98% in 476 ms
/// against 1.4.
pub const MAXRECTS_MAX_CHARTS: usize = 200;

/// Factor by which the texel scale shrinks after a failed packing: ten percent per try keeps the
/// found scale within ten percent of the largest that packs, in a few dozen tries at most.
const SCALE_STEP: f64 = 0.9;

/// Bisections after the first scale that packs: four cut the ten percent gap of one step to
/// under one percent (in log scale, 1/16 of it).
const REFINE_STEPS: usize = 4;

/// Growth of the square tried when tightening the atlas around the charts: five percent wastes
/// at most a tenth of the area over the tightest square the packer manages.
const TIGHTEN_STEP: f64 = 1.05;

/// Packs rectangles of the given `(width, height)` sizes, each with `gutter` texels around it,
/// into a `max_side x max_side` square. `None` when they do not all fit, or a size is zero. The
/// returned layout is cropped to the packed extent.
pub fn pack_rects(sizes: &[(u32, u32)], gutter: u32, max_side: u32) -> Option<Layout> {
    let side = max_side.min(PACKER_MAX_SIDE);
    // Padded sizes; no rotation: a rotated chart would need its UVs rotated too, for little gain.
    let mut padded = Vec::with_capacity(sizes.len());
    for &(w, h) in sizes {
        if w == 0 || h == 0 {
            return None;
        }
        let pw = u32::try_from(u64::from(w) + 2 * u64::from(gutter)).ok()?;
        let ph = u32::try_from(u64::from(h) + 2 * u64::from(gutter)).ok()?;
        if pw > side || ph > side {
            return None;
        }
        padded.push((pw, ph));
    }
    let corners = if sizes.len() <= MAXRECTS_MAX_CHARTS {
        pack_maximal_rectangles(&padded, side)?
    } else {
        pack_guillotine(&padded, side)?
    };
    let mut rects = Vec::with_capacity(sizes.len());
    let (mut width, mut height) = (0u32, 0u32);
    for ((x0, y0), &(w, h)) in corners.into_iter().zip(sizes) {
        rects.push(PackedRect {
            x: x0 + gutter,
            y: y0 + gutter,
            width: w,
            height: h,
        });
        width = width.max(x0 + w + 2 * gutter);
        height = height.max(y0 + h + 2 * gutter);
    }
    Some(Layout {
        width,
        height,
        gutter,
        rects,
    })
}

/// The top-left corner of every padded rectangle in a `side x side` square, by `crunch`.
fn pack_maximal_rectangles(padded: &[(u32, u32)], side: u32) -> Option<Vec<(u32, u32)>> {
    let items = padded
        .iter()
        .enumerate()
        .map(|(i, &(w, h))| crunch::Item::new(i, w as usize, h as usize, crunch::Rotation::None));
    let square = crunch::Rect::of_size(side as usize, side as usize);
    let packed = crunch::pack(square, items).ok()?;
    let mut corners = vec![None; padded.len()];
    for item in packed {
        let r = item.rect;
        *corners.get_mut(item.data)? = Some((u32::try_from(r.x).ok()?, u32::try_from(r.y).ok()?));
    }
    corners.into_iter().collect()
}

/// The same by `guillotiere`, offered largest area first (ties by index, so the layout is
/// deterministic).
fn pack_guillotine(padded: &[(u32, u32)], side: u32) -> Option<Vec<(u32, u32)>> {
    let mut order: Vec<usize> = (0..padded.len()).collect();
    order.sort_by_key(|&i| {
        (
            std::cmp::Reverse(u64::from(padded[i].0) * u64::from(padded[i].1)),
            i,
        )
    });
    let side = i32::try_from(side).ok()?;
    let mut allocator = guillotiere::AtlasAllocator::new(guillotiere::size2(side, side));
    let mut corners = vec![(0, 0); padded.len()];
    for i in order {
        let (w, h) = padded[i];
        let size = guillotiere::size2(i32::try_from(w).ok()?, i32::try_from(h).ok()?);
        let min = allocator.allocate(size)?.rectangle.min;
        corners[i] = (u32::try_from(min.x).ok()?, u32::try_from(min.y).ok()?);
    }
    Some(corners)
}

/// Finds the largest global texel scale <= 1 at which every chart, `ceil(natural size x scale)`
/// texels and at least one per axis, packs into `side x side`, then the smallest square that
/// still holds them, and returns the validated layout with that scale.
///
/// The scale shrinks geometrically by [`SCALE_STEP`] until the charts pack, then
/// [`REFINE_STEPS`] bisections between the last failure and the first success recover most of
/// the step.
pub(crate) fn pack_charts(
    charts: &[Chart],
    gutter: u32,
    side: u32,
) -> Result<(Layout, f32), AtlasError> {
    let natural: Vec<DVec2> = charts.iter().map(Chart::natural).collect();
    let sizes_at = |scale: f64| -> Vec<(u32, u32)> {
        natural
            .iter()
            .map(|n| {
                let s = (*n * scale).ceil().max(DVec2::ONE);
                (
                    s.x.min(f64::from(u32::MAX)) as u32,
                    s.y.min(f64::from(u32::MAX)) as u32,
                )
            })
            .collect()
    };
    // No packing beats area: above the scale s at which the padded charts' area
    // sum (n.x s + 2g)(n.y s + 2g) equals the square's, nothing fits (ceil only adds area).
    let g = f64::from(gutter);
    let a: f64 = natural.iter().map(|n| n.x * n.y).sum();
    let b: f64 = natural.iter().map(|n| 2.0 * g * (n.x + n.y)).sum();
    let c = 4.0 * g * g * natural.len() as f64 - f64::from(side.min(PACKER_MAX_SIDE)).powi(2);
    let mut scale = if a > 0.0 && c < 0.0 {
        ((-b + (b * b - 4.0 * a * c).sqrt()) / (2.0 * a)).min(1.0)
    } else {
        1.0
    };
    // Shrink geometrically until everything packs.
    let mut failed_above = None;
    let mut layout = loop {
        let sizes = sizes_at(scale);
        if let Some(layout) = pack_rects(&sizes, gutter, side) {
            break layout;
        }
        if sizes.iter().all(|&s| s == (1, 1)) {
            return Err(AtlasError::DoesNotFit {
                charts: charts.len(),
                side,
            });
        }
        failed_above = Some(scale);
        scale *= SCALE_STEP;
    };
    // Bisect (geometrically) between the packing scale and the failing one above it.
    if let Some(mut hi) = failed_above {
        for _ in 0..REFINE_STEPS {
            let mid = (scale * hi).sqrt();
            match pack_rects(&sizes_at(mid), gutter, side) {
                Some(better) => {
                    scale = mid;
                    layout = better;
                }
                None => hi = mid,
            }
        }
    }
    // The packer spreads rectangles over the whole square it is given; find the smallest square
    // that holds them at this scale, so the cropped atlas wastes little.
    let sizes = sizes_at(scale);
    let padded_area: u64 = sizes
        .iter()
        .map(|&(w, h)| {
            (u64::from(w) + 2 * u64::from(gutter)) * (u64::from(h) + 2 * u64::from(gutter))
        })
        .sum();
    let longest = sizes
        .iter()
        .map(|&(w, h)| w.max(h) + 2 * gutter)
        .max()
        .unwrap_or(0);
    // Walk up from the area bound in small steps: a good packer fills most of the square, so
    // the first few tries usually succeed, and each try costs a full packing.
    let bound = layout.width.max(layout.height);
    let mut try_side = longest.max((padded_area as f64).sqrt().ceil() as u32);
    while try_side < bound {
        if let Some(tighter) = pack_rects(&sizes, gutter, try_side) {
            layout = tighter;
            break;
        }
        try_side = ((f64::from(try_side) * TIGHTEN_STEP).ceil() as u32).max(try_side + 1);
    }
    layout.validate()?;
    Ok((layout, scale as f32))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_squares_side_by_side() {
        // Two 4x4 rectangles with a gutter of 1 are 6x6 each; a 12x6 strip holds both, and a
        // 12x12 square is enough room.
        let layout = pack_rects(&[(4, 4), (4, 4)], 1, 12).expect("two 6x6 fit in 12x12");
        layout.validate().expect("valid layout");
        assert_eq!(layout.rects.len(), 2);
        assert!(layout.width * layout.height >= 72);
    }

    #[test]
    fn too_big_does_not_fit() {
        // A 10x10 rectangle with a gutter of 1 needs 12 texels per side.
        assert!(pack_rects(&[(10, 10)], 1, 11).is_none());
        assert!(pack_rects(&[(10, 10)], 1, 12).is_some());
    }
}
