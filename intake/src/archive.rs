//! Zip uploads: researchers submit the seven core datasets as one `.zip` of result files
//! named the BOP way (`METHOD_DATASET-SPLIT.csv`), and the archive becomes the files of an
//! ordinary upload of several files, so that everything after unpacking (dataset from the
//! name, checks, one submission per file, all or none) is the one flow of the server's
//! `submissions` service.
//!
//! An archive is hostile until read: the unpacked size and the number of entries are counted
//! while reading, never taken from the headers (a zip bomb declares small sizes and inflates
//! a thousandfold); before the `zip` crate builds its index, the entry counts declared by
//! every end-of-central-directory record in the archive's tail are checked too, because the
//! crate allocates per declared entry. Entry names are only used for display and the
//! dataset: nothing is written under them, names that leave the archive (`../`, absolute
//! paths) are refused all the same, as are symbolic links, nested archives and any entry
//! other than a `.csv` file, each named in the refusal. Folders are allowed (archivers add a
//! top folder), and macOS's `__MACOSX/` resource forks are skipped since Finder adds them to
//! every archive.
//!
//! The `zip` crate is used with `default-features = false` and only `deflate-flate2`: reading
//! Deflate (what every archiver writes by default) and Stored, in pure Rust. Pitfalls: the
//! default features pull in AES, bzip2, LZMA, zstd and zopfli, C code among them; the
//! `deflate-flate2` feature names no flate2 backend: it gets the one the other flate2 users of
//! the build choose (the evaluator's `zlib-rs`, with which it inflates depth PNGs, takes
//! precedence over the default miniz_oxide that `tiff` and tower-http's gzip bring); without
//! them flate2 stops with "You need to choose a zlib backend"; an entry compressed any other
//! way (bzip2, LZMA, ...) or encrypted is refused saying so; and the crate's streaming reader
//! cannot read entries with data descriptors (which macOS Finder writes), so the archive is
//! read through its central directory.

use std::io::{Read, Seek, SeekFrom, Write};
use std::path::Path;

use sha2::{Digest, Sha256};

use crate::UploadedFile;

/// Most entries an archive may hold, folders and skipped ones included.
const MAX_ENTRIES: usize = 64;
/// Most result files in one archive: one per dataset, and BOP has fewer than twenty.
const MAX_FILES: usize = 20;
/// An end-of-central-directory record lies within the last 22 bytes plus a comment of at
/// most 65535.
const EOCD_TAIL: u64 = 22 + 65_535;
const EOCD_SIGNATURE: [u8; 4] = *b"PK\x05\x06";
const ZIP64_LOCATOR_SIGNATURE: [u8; 4] = *b"PK\x06\x07";

/// Why an archive gives no result files. Each message starts with the archive's name.
#[derive(Debug, thiserror::Error)]
pub enum ArchiveError {
    /// The archive as a whole cannot be taken (unreadable, too many entries, too large, ...).
    #[error("{0}")]
    Invalid(String),
    /// Entries that may not be in an archive of result files, each named: none is taken.
    #[error("{message}")]
    Refused {
        message: String,
        entries: Vec<RefusedEntry>,
    },
    /// Reading the upload or writing an entry out failed: the service's fault, not the
    /// archive's.
    #[error(transparent)]
    Io(#[from] std::io::Error),
}

/// One refused entry: `file` is `ARCHIVE:ENTRY`, as the answer lists problems per file.
#[derive(Clone, Debug)]
pub struct RefusedEntry {
    pub file: String,
    pub message: String,
}

/// Whether an uploaded file is a zip archive to unpack (by the name the client gave it).
pub fn is_zip(file: &UploadedFile) -> bool {
    file.name.to_ascii_lowercase().ends_with(".zip")
}

/// Unpacks the `.csv` entries of the archive `archive_name` read from `reader` into temporary
/// files of `dir`, in archive order, under `limit` bytes unpacked in all. Blocking: call it
/// off the async threads.
pub fn unpack<R: Read + Seek>(
    dir: &Path,
    archive_name: &str,
    mut reader: R,
    limit: u64,
) -> Result<Vec<UploadedFile>, ArchiveError> {
    let invalid = |message: String| ArchiveError::Invalid(format!("{archive_name}: {message}"));
    check_declared_entries(&mut reader, archive_name)?;
    let mut archive = zip::ZipArchive::new(reader)
        .map_err(|e| invalid(format!("not a readable zip archive ({e})")))?;
    if archive.len() > MAX_ENTRIES {
        return Err(too_many(archive_name, archive.len()));
    }

    let mut refused = Vec::new();
    let mut files = Vec::new();
    let mut unpacked = 0u64;
    for index in 0..archive.len() {
        let listed = archive
            .name_for_index(index)
            .and_then(Result::ok)
            .map_or_else(|| format!("#{index}"), |n| n.into_owned());
        let mut entry = match archive.by_index(index) {
            Ok(entry) => entry,
            Err(e) => {
                refused.push(refusal(
                    archive_name,
                    &listed,
                    &format!("cannot be read ({e})"),
                ));
                continue;
            }
        };
        let name = entry.name().map_or_else(
            |_| String::from_utf8_lossy(entry.name_raw()).into_owned(),
            |n| n.into_owned(),
        );
        if name.starts_with("__MACOSX/") {
            continue;
        }
        let Some(path) = entry.enclosed_name() else {
            refused.push(refusal(
                archive_name,
                &name,
                "has a path that leaves the archive (absolute or with `..`)",
            ));
            continue;
        };
        if entry.is_dir() {
            continue;
        }
        if entry.is_symlink() {
            refused.push(refusal(archive_name, &name, "is a symbolic link"));
            continue;
        }
        let base = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if !base.to_ascii_lowercase().ends_with(".csv") {
            refused.push(refusal(
                archive_name,
                &name,
                "is not a result file: an archive may hold only METHOD_DATASET-SPLIT.csv files",
            ));
            continue;
        }
        if files.len() == MAX_FILES {
            return Err(invalid(format!(
                "more than {MAX_FILES} result files: one per dataset is expected"
            )));
        }
        let file = copy_entry(dir, &mut entry, &base, limit.saturating_sub(unpacked)).map_err(
            |e| match e {
                Copy::TooLarge => invalid(format!(
                    "unpacks to more than {limit} bytes, the upload limit (at entry {name})"
                )),
                Copy::Zip(e) => invalid(format!("entry {name} cannot be unpacked ({e})")),
                Copy::Io(e) => ArchiveError::Io(e),
            },
        )?;
        unpacked += file.size;
        files.push(file);
    }
    if !refused.is_empty() {
        return Err(ArchiveError::Refused {
            message: format!(
                "{archive_name}: {} entries are refused, so nothing was submitted: {}",
                refused.len(),
                refused
                    .iter()
                    .map(|p| p.message.as_str())
                    .collect::<Vec<_>>()
                    .join("; ")
            ),
            entries: refused,
        });
    }
    if files.is_empty() {
        return Err(invalid("holds no result file (.csv)".into()));
    }
    Ok(files)
}

fn refusal(archive: &str, entry: &str, what: &str) -> RefusedEntry {
    RefusedEntry {
        file: format!("{archive}:{entry}"),
        message: format!("entry {entry} {what}"),
    }
}

fn too_many(archive: &str, entries: usize) -> ArchiveError {
    ArchiveError::Invalid(format!(
        "{archive}: {entries} entries, more than the {MAX_ENTRIES} an archive of result files \
         may hold"
    ))
}

/// Refuses an archive whose tail declares more entries than allowed, in any of its
/// end-of-central-directory records (a second one may hide in the comment of the first), or
/// that needs ZIP64 (result archives are far below its 65535 entries and 4 GiB).
fn check_declared_entries<R: Read + Seek>(
    reader: &mut R,
    archive: &str,
) -> Result<(), ArchiveError> {
    let len = reader.seek(SeekFrom::End(0))?;
    let start = len.saturating_sub(EOCD_TAIL);
    reader.seek(SeekFrom::Start(start))?;
    let mut tail = Vec::new();
    reader.take(EOCD_TAIL).read_to_end(&mut tail)?;
    reader.seek(SeekFrom::Start(0))?;
    for at in 0..tail.len().saturating_sub(3) {
        let signature = &tail[at..at + 4];
        if signature == ZIP64_LOCATOR_SIGNATURE {
            return Err(ArchiveError::Invalid(format!(
                "{archive}: a ZIP64 archive; result archives are small, write a plain zip"
            )));
        }
        if signature == EOCD_SIGNATURE
            && let Some(count) = tail.get(at + 10..at + 12)
        {
            let declared = usize::from(u16::from_le_bytes([count[0], count[1]]));
            if declared > MAX_ENTRIES {
                return Err(too_many(archive, declared));
            }
        }
    }
    Ok(())
}

enum Copy {
    TooLarge,
    Zip(std::io::Error),
    Io(std::io::Error),
}

/// Copies one entry to a temporary file, hashing it, stopping as soon as more than `room`
/// bytes came out (whatever the entry's header says).
fn copy_entry(
    dir: &Path,
    entry: &mut impl Read,
    name: &str,
    room: u64,
) -> Result<UploadedFile, Copy> {
    let mut out = tempfile::Builder::new()
        .prefix("upload-")
        .tempfile_in(dir)
        .map_err(Copy::Io)?;
    let mut hasher = Sha256::new();
    let mut size = 0u64;
    let mut buf = vec![0u8; 64 * 1024];
    loop {
        // Decompression and CRC errors come from the entry; write errors from our disk.
        let n = entry.read(&mut buf).map_err(Copy::Zip)?;
        if n == 0 {
            break;
        }
        size += n as u64;
        if size > room {
            return Err(Copy::TooLarge);
        }
        hasher.update(&buf[..n]);
        out.write_all(&buf[..n]).map_err(Copy::Io)?;
    }
    out.flush().map_err(Copy::Io)?;
    Ok(UploadedFile {
        name: name.chars().filter(|c| !c.is_control()).take(200).collect(),
        tmp: out.into_temp_path(),
        sha256: hex::encode(hasher.finalize()),
        size,
    })
}

#[cfg(test)]
mod tests {
    use std::io::Cursor;

    use super::*;

    fn zip_of(entries: &[(&str, &[u8])]) -> Vec<u8> {
        let mut w = zip::ZipWriter::new(Cursor::new(Vec::new()));
        let options = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Deflated);
        for (name, bytes) in entries {
            w.start_file(*name, options).expect("entry");
            w.write_all(bytes).expect("write");
        }
        w.finish().expect("zip").into_inner()
    }

    fn unpack_bytes(bytes: &[u8], limit: u64) -> Result<Vec<UploadedFile>, ArchiveError> {
        let dir = tempfile::tempdir().expect("tmp");
        unpack(dir.path(), "r.zip", Cursor::new(bytes), limit)
    }

    #[test]
    fn result_files_come_out_hashed_under_their_base_name() {
        let zip = zip_of(&[
            ("results/a_lmo-test.csv", b"scene_id\n"),
            ("__MACOSX/results/._a_lmo-test.csv", b"\0"),
        ]);
        let files = unpack_bytes(&zip, 1 << 20).expect("unpacked");
        assert_eq!(files.len(), 1);
        assert_eq!(files[0].name, "a_lmo-test.csv");
        assert_eq!(files[0].size, 9);
        assert_eq!(files[0].sha256, hex::encode(Sha256::digest(b"scene_id\n")));
    }

    #[test]
    fn the_limit_holds_for_what_comes_out() {
        let bomb = vec![b'1'; 1 << 20];
        let zip = zip_of(&[("bomb_lmo-test.csv", &bomb)]);
        assert!(zip.len() < 10_000, "{}", zip.len());
        let e = unpack_bytes(&zip, 1000).expect_err("over the limit");
        assert!(
            e.to_string()
                .contains("r.zip: unpacks to more than 1000 bytes"),
            "{e}"
        );
    }

    #[test]
    fn refused_entries_are_each_named() {
        let zip = zip_of(&[
            ("a_lmo-test.csv", b"x"),
            ("notes.txt", b"x"),
            ("../b.csv", b"x"),
        ]);
        let Err(ArchiveError::Refused { entries, .. }) = unpack_bytes(&zip, 1 << 20) else {
            panic!("refused");
        };
        let named: Vec<&str> = entries.iter().map(|e| e.file.as_str()).collect();
        assert_eq!(named, ["r.zip:notes.txt", "r.zip:../b.csv"]);
    }

    #[test]
    fn bytes_that_are_no_archive_are_refused() {
        for bytes in [&b""[..], b"not a zip", b"PK\x05\x06"] {
            let e = unpack_bytes(bytes, 1 << 20).expect_err("no archive");
            assert!(matches!(e, ArchiveError::Invalid(_)), "{e}");
        }
    }
}
