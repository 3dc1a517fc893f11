//! The AOVs of a render as one multi-layer OpenEXR file (`aovs.exr`, beside the PFMs): one
//! image part whose channels are named `layer.channel` (`color.R`, `depth.Z`, `normal.X`,
//! `work.steps`, ...), the convention pbrt-v4, Mitsuba, Blender and Nuke read as layers.
//! 32-bit float samples, lossless ZIP compression, rows top to bottom.

use anyhow::{Context, Result};
use exr::prelude::*;
use marchmesh_core::Framebuffer;

/// The file name of the EXR written into the `--aov` folder.
pub const AOV_EXR_NAME: &str = "aovs.exr";

/// The layers and channels written, in the order their samples are taken from a pixel.
pub const CHANNELS: [&str; 13] = [
    "color.R",
    "color.G",
    "color.B",
    "depth.Z",
    "normal.X",
    "normal.Y",
    "normal.Z",
    "mask.A",
    "work.steps",
    "work.nodes",
    "work.primitives",
    "termination.id",
    "material.id",
];

/// The EXR bytes of `fb`'s AOVs: colour (linear), depth (infinite where nothing is hit),
/// normal, hit mask (1 hit, 0 miss), the work counters (sdf steps, BVH nodes, primitive
/// tests), the termination reason and the material index, as in the PFMs.
///
/// Errors: the EXR encoder fails (an image of zero pixels).
pub fn encode(fb: &Framebuffer) -> Result<Vec<u8>> {
    let plane = |f: &dyn Fn(usize) -> f32| -> FlatSamples {
        FlatSamples::F32((0..fb.depth.len()).map(f).collect())
    };
    let planes: [FlatSamples; 13] = [
        plane(&|i| fb.color[i].x),
        plane(&|i| fb.color[i].y),
        plane(&|i| fb.color[i].z),
        plane(&|i| fb.depth[i]),
        plane(&|i| fb.normal[i].x),
        plane(&|i| fb.normal[i].y),
        plane(&|i| fb.normal[i].z),
        plane(&|i| if fb.depth[i].is_finite() { 1.0 } else { 0.0 }),
        plane(&|i| fb.work[i].steps as f32),
        plane(&|i| fb.work[i].node_visits as f32),
        plane(&|i| fb.work[i].primitive_tests as f32),
        plane(&|i| fb.termination[i] as u8 as f32),
        plane(&|i| fb.material.get(i).map_or(0.0, |&m| m as f32)),
    ];
    let list: Vec<AnyChannel<FlatSamples>> = CHANNELS
        .iter()
        .zip(planes)
        .map(|(name, samples)| AnyChannel::new(*name, samples))
        .collect();
    let channels = AnyChannels::sort(SmallVec::from_vec(list));
    let layer = Layer::new(
        (fb.width as usize, fb.height as usize),
        LayerAttributes::named("aovs"),
        Encoding::SMALL_LOSSLESS,
        channels,
    );
    let mut bytes = std::io::Cursor::new(Vec::new());
    Image::from_layer(layer)
        .write()
        .to_buffered(&mut bytes)
        .context("encoding the AOVs as OpenEXR")?;
    Ok(bytes.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_aov_is_a_named_channel_with_its_values() {
        let mut fb = Framebuffer::new(3, 2);
        fb.depth.iter_mut().for_each(|d| *d = f32::INFINITY);
        fb.depth[4] = 2.5;
        fb.color[4].y = 0.75;
        fb.normal[4].z = -1.0;
        let bytes = encode(&fb).unwrap();
        let image = read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .all_layers()
            .all_attributes()
            .from_buffered(std::io::Cursor::new(bytes))
            .unwrap();
        let layer = &image.layer_data[0];
        assert_eq!(layer.size, Vec2(3, 2));
        let value = |name: &str, i: usize| {
            let ch = layer
                .channel_data
                .list
                .iter()
                .find(|c| c.name.eq(name))
                .unwrap_or_else(|| panic!("no channel {name}"));
            ch.sample_data.value_by_flat_index(i).to_f32()
        };
        assert_eq!(layer.channel_data.list.len(), CHANNELS.len());
        assert_eq!(value("depth.Z", 4), 2.5);
        assert!(value("depth.Z", 0).is_infinite());
        assert_eq!(value("color.G", 4), 0.75);
        assert_eq!(value("normal.Z", 4), -1.0);
        assert_eq!((value("mask.A", 4), value("mask.A", 0)), (1.0, 0.0));
    }
}
