//! The arguments of the commands whose bodies live in this crate or below it, and their
//! dispatch: `roomlight graycode` (roomlight-calib through `graycode_files`) and `roomlight certs`
//! (the room's CA and certificates, `roomlight_agent::tls`). The binary only names them; nothing
//! here knows config files.

use crate::graycode_files::{decode_folder, generate};
use anyhow::Result;
use clap::{Subcommand, ValueEnum};
use roomlight_agent::tls;
use roomlight_calib::image_io::{Depth, Encoding};
use std::net::IpAddr;
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

/// `roomlight graycode generate|decode`: structured light on real photographs.
pub fn graycode(command: GraycodeCommand) -> Result<()> {
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

#[derive(Debug, Subcommand)]
pub enum CertsCommand {
    /// Makes the room's CA: DIR/ca.pem and DIR/ca.key (0600). Keep the key off the room's PCs.
    Init {
        /// The folder DIR the CA is written to.
        #[arg(long)]
        out: PathBuf,
    },
    /// Issues a certificate signed by the room's CA: OUT/NAME.pem and OUT/NAME.key (0600), and
    /// the CA's certificate as OUT/ca.pem (what one PC needs).
    Issue {
        /// The folder of `certs init`.
        #[arg(long)]
        ca: PathBuf,
        /// A node's projector id, or the camera agent's name (node agents that find it over
        /// mDNS expect the room's name; see docs/operations.md).
        #[arg(long)]
        name: String,
        /// Another DNS name the agent is reached by (repeatable).
        #[arg(long)]
        dns: Vec<String>,
        /// An IP address the agent is reached by, for nodes that name it (repeatable).
        #[arg(long)]
        ip: Vec<IpAddr>,
        /// The folder OUT the certificate, its key and the CA's certificate are written to.
        #[arg(long, default_value = ".")]
        out: PathBuf,
    },
}

/// `roomlight certs init|issue`: prints the files written.
pub fn certs(command: CertsCommand) -> Result<()> {
    let wrote = match command {
        CertsCommand::Init { out } => tls::init_ca(&out)?,
        CertsCommand::Issue {
            ca,
            name,
            dns,
            ip,
            out,
        } => tls::issue(&ca, &tls::Subject { name, dns, ip }, &out)?,
    };
    for path in wrote {
        println!("wrote {}", path.display());
    }
    Ok(())
}
