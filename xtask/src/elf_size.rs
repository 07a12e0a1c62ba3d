//! Flash and RAM use of the firmware ELF, read from its section headers (the same
//! arithmetic as `size -A`, done here so the test command needs no ARM binutils).

use object::{Object, ObjectSection, SectionFlags};
use std::path::Path;

/// Where the image's bytes go.
pub struct Size {
    /// Bytes stored in flash: code, read-only data and the initial values of `.data`.
    pub flash: u64,
    /// Bytes of statically allocated RAM (all data regions; ITCM code not included).
    pub ram: u64,
    /// Bytes per RAM region (named as in `memory.x`, ITCM included), largest first.
    pub regions: Vec<(String, u64)>,
}

/// Region of an address, per `memory.x`.
fn region(addr: u64) -> &'static str {
    match addr {
        0x0000_0000..=0x0000_FFFF => "ITCM",
        0x0800_0000..=0x081F_FFFF => "FLASH",
        0x2000_0000..=0x2001_FFFF => "DTCM",
        0x2400_0000..=0x2407_FFFF => "AXISRAM",
        0x3000_0000..=0x3004_7FFF => "SRAM1-3",
        0x3800_0000..=0x3800_FFFF => "SRAM4",
        _ => "other",
    }
}

/// Reads the section table of `elf`.
pub fn read(elf: &Path) -> Result<Size, String> {
    let data = std::fs::read(elf).map_err(|e| format!("cannot read {}: {e}", elf.display()))?;
    let file =
        object::File::parse(&*data).map_err(|e| format!("{}: not an ELF: {e}", elf.display()))?;
    let mut flash = 0;
    let mut ram = 0;
    let mut regions: Vec<(String, u64)> = Vec::new();
    for section in file.sections() {
        let SectionFlags::Elf { sh_flags } = section.flags() else {
            continue;
        };
        // SHF_ALLOC: the section occupies memory at run time.
        if sh_flags & u64::from(object::elf::SHF_ALLOC) == 0 || section.size() == 0 {
            continue;
        }
        let addr = section.address();
        let in_file = section.file_range().is_some();
        let place = region(addr);
        if place == "FLASH" {
            flash += section.size();
            continue;
        }
        // A RAM section with file contents (.data, .dtcm, the code in .itcm) is also
        // stored in flash, as the image the start-up code copies.
        if in_file {
            flash += section.size();
        }
        // ITCM holds code: counted per region below, not as static RAM.
        if place != "ITCM" {
            ram += section.size();
        }
        match regions.iter_mut().find(|(n, _)| n == place) {
            Some((_, b)) => *b += section.size(),
            None => regions.push((place.to_string(), section.size())),
        }
    }
    regions.sort_by_key(|r| std::cmp::Reverse(r.1));
    Ok(Size {
        flash,
        ram,
        regions,
    })
}
