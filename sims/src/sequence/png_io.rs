//! PNG reading and writing for recorded sequences: 16-bit grey depth, and grey or
//! colour intensity images.

use std::io::{BufReader, BufWriter};
use std::path::Path;

use super::SequenceError;

/// A decoded image with one value per pixel.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Plane<T> {
    pub width: u32,
    pub height: u32,
    pub data: Vec<T>,
}

fn bad(path: &Path, reason: impl Into<String>) -> SequenceError {
    SequenceError::BadImage {
        path: path.to_path_buf(),
        reason: reason.into(),
    }
}

fn decode(path: &Path) -> Result<(png::OutputInfo, Vec<u8>), SequenceError> {
    let file = std::fs::File::open(path).map_err(|source| SequenceError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mut decoder = png::Decoder::new(BufReader::new(file));
    // Expand palettes and low bit depths to 8 bits; keep 16-bit samples.
    decoder.set_transformations(png::Transformations::EXPAND);
    let mut reader = decoder.read_info().map_err(|e| bad(path, e.to_string()))?;
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| bad(path, "image too large"))?;
    let mut buf = vec![0u8; size];
    let info = reader
        .next_frame(&mut buf)
        .map_err(|e| bad(path, e.to_string()))?;
    buf.truncate(info.line_size * info.height as usize);
    Ok((info, buf))
}

/// Read a 16-bit single-channel depth PNG (raw units; the camera file's
/// `depth_scale` turns them into metres).
pub(crate) fn read_depth(path: &Path) -> Result<Plane<u16>, SequenceError> {
    let (info, buf) = decode(path)?;
    if info.color_type != png::ColorType::Grayscale || info.bit_depth != png::BitDepth::Sixteen {
        return Err(bad(
            path,
            format!(
                "depth must be a 16-bit greyscale PNG, found {:?} at {:?} bits",
                info.color_type, info.bit_depth
            ),
        ));
    }
    let data = buf
        .chunks_exact(2)
        .map(|c| u16::from_be_bytes([c[0], c[1]]))
        .collect();
    Ok(Plane {
        width: info.width,
        height: info.height,
        data,
    })
}

/// Read an intensity image as values in [0, 1]: grey as is, colour as Rec. 601 luma
/// (`0.299 R + 0.587 G + 0.114 B`); alpha is ignored; 8 or 16 bits.
pub(crate) fn read_intensity(path: &Path) -> Result<Plane<f32>, SequenceError> {
    let (info, buf) = decode(path)?;
    let channels = match info.color_type {
        png::ColorType::Grayscale => 1,
        png::ColorType::GrayscaleAlpha => 2,
        png::ColorType::Rgb => 3,
        png::ColorType::Rgba => 4,
        png::ColorType::Indexed => return Err(bad(path, "palette was not expanded")),
    };
    let (bytes, max) = match info.bit_depth {
        png::BitDepth::Eight => (1, 255.0f32),
        png::BitDepth::Sixteen => (2, 65535.0f32),
        other => return Err(bad(path, format!("unsupported bit depth {other:?}"))),
    };
    let sample = |px: &[u8], c: usize| -> f32 {
        if bytes == 1 {
            f32::from(px[c])
        } else {
            f32::from(u16::from_be_bytes([px[2 * c], px[2 * c + 1]]))
        }
    };
    let data = buf
        .chunks_exact(channels * bytes)
        .map(|px| {
            let v = if channels >= 3 {
                0.299 * sample(px, 0) + 0.587 * sample(px, 1) + 0.114 * sample(px, 2)
            } else {
                sample(px, 0)
            };
            (v / max).clamp(0.0, 1.0)
        })
        .collect();
    Ok(Plane {
        width: info.width,
        height: info.height,
        data,
    })
}

fn encode(
    path: &Path,
    width: u32,
    height: u32,
    depth: png::BitDepth,
    data: &[u8],
) -> Result<(), SequenceError> {
    let io = |source| SequenceError::Io {
        path: path.to_path_buf(),
        source,
    };
    let file = std::fs::File::create(path).map_err(io)?;
    let mut encoder = png::Encoder::new(BufWriter::new(file), width, height);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(depth);
    let mut writer = encoder
        .write_header()
        .map_err(|e| bad(path, e.to_string()))?;
    writer
        .write_image_data(data)
        .map_err(|e| bad(path, e.to_string()))?;
    writer.finish().map_err(|e| bad(path, e.to_string()))
}

/// Write a 16-bit greyscale PNG.
pub(crate) fn write_depth(path: &Path, plane: &Plane<u16>) -> Result<(), SequenceError> {
    let bytes: Vec<u8> = plane.data.iter().flat_map(|v| v.to_be_bytes()).collect();
    encode(
        path,
        plane.width,
        plane.height,
        png::BitDepth::Sixteen,
        &bytes,
    )
}

/// Write intensities in [0, 1] as an 8-bit greyscale PNG.
pub(crate) fn write_intensity(path: &Path, plane: &Plane<f32>) -> Result<(), SequenceError> {
    let bytes: Vec<u8> = plane
        .data
        .iter()
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    encode(
        path,
        plane.width,
        plane.height,
        png::BitDepth::Eight,
        &bytes,
    )
}
