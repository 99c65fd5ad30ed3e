//! `roomlight graycode generate|decode`: structured light on real photographs.

use anyhow::Result;
use clap::{Subcommand, ValueEnum};
use roomlight_calib::image_io::{Depth, Encoding};
use roomlight_lab::graycode_files::{decode_folder, generate};
use std::path::PathBuf;

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum DepthArg {
    /// 8 bits per channel.
    #[value(name = "8")]
    Eight,
    /// 16 bits per channel.
    #[value(name = "16")]
    Sixteen,
    /// Either.
    Any,
}

#[derive(Debug, Subcommand)]
pub enum GraycodeCommand {
    /// Writes the patterns of a projector as PNG and DIR/patterns.json.
    Generate {
        /// Projector width in pixels (at most 8192, refused before anything is rendered).
        #[arg(long)]
        width: u32,
        /// Projector height in pixels (at most 8192).
        #[arg(long)]
        height: u32,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
    },
    /// Decodes captures named like the patterns into a 16-bit map
    /// (R = column + 1, G = row + 1, 0 where unknown, B = confidence × 65535). Refuses captures
    /// over 12000 pixels a side, saturated ones, and a projector the captures did not see.
    Decode {
        /// The patterns.json written by `generate`.
        #[arg(long)]
        patterns: PathBuf,
        /// Folder with one capture per pattern, same file names.
        #[arg(long)]
        captures: PathBuf,
        /// Output PNG.
        #[arg(long)]
        out: PathBuf,
        /// The captures hold linear values (default: sRGB-encoded).
        #[arg(long)]
        linear: bool,
        /// Bit depth the captures must have.
        #[arg(long, value_enum, default_value = "any")]
        depth: DepthArg,
    },
}

pub fn run(command: GraycodeCommand) -> Result<()> {
    match command {
        GraycodeCommand::Generate { width, height, out } => {
            println!("{}", generate(width, height, &out)?);
        }
        GraycodeCommand::Decode {
            patterns,
            captures,
            out,
            linear,
            depth,
        } => {
            let depth = match depth {
                DepthArg::Eight => Depth::Eight,
                DepthArg::Sixteen => Depth::Sixteen,
                DepthArg::Any => Depth::Any,
            };
            let encoding = if linear {
                Encoding::Linear
            } else {
                Encoding::Srgb
            };
            println!(
                "{}",
                decode_folder(&patterns, &captures, &out, encoding, depth)?
            );
        }
    }
    Ok(())
}
