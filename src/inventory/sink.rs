//! [`Sink`]: the reads' destination (a reads file, CSV or standard output), written in whole
//! lines.

use std::io::{self, Write};

use super::Output;
use crate::reads::{self, Read};
use llrp_gateway_vocab::table::CsvWriter;

/// Bytes of whole lines buffered before they are written out.
const SINK_BUFFER: usize = 64 * 1024;

/// The reads' destination, open. Lines are buffered here and written out whole (when the
/// buffer fills, and at each flush), so the file never ends in a partial line between
/// writes: a reader following it live only ever sees whole reads.
pub(super) struct Sink {
    out: Option<Box<dyn Write>>,
    /// CSV rows, quoted where a cell needs it, when the destination is CSV.
    csv: Option<CsvWriter>,
    buf: Vec<u8>,
}

impl Sink {
    /// Opens the destination; an existing file is refused unless `force`.
    pub(super) fn open(output: &Option<Output>, force: bool) -> io::Result<Sink> {
        let create = |p| crate::files::create_stream(p, &[], force).map_err(|e| e.into_io());
        let (out, csv): (Option<Box<dyn Write>>, bool) = match output {
            None => (None, false),
            Some(Output::Stdout) => (Some(Box::new(io::stdout())), false),
            Some(Output::Jsonl(p)) => (Some(Box::new(create(p)?)), false),
            Some(Output::Csv(p)) => (Some(Box::new(create(p)?)), true),
            Some(Output::Unnamed(p)) => {
                return Err(io::Error::other(format!(
                "{}: the format is not settled (cli::inventory::InventoryArgs::resolved_output)",
                p.display()
            )))
            }
        };
        let mut sink = Sink {
            out,
            csv: csv.then(CsvWriter::new),
            buf: Vec::with_capacity(SINK_BUFFER),
        };
        if let Some(w) = &mut sink.csv {
            w.row(reads::CSV_HEADER.split(','))?;
            sink.flush()?;
        }
        Ok(sink)
    }

    pub(super) fn write(&mut self, r: &Read) -> io::Result<()> {
        if self.out.is_none() {
            return Ok(());
        }
        let buffered = match &mut self.csv {
            Some(w) => {
                w.row(r.csv_cells())?;
                w.buffered().len()
            }
            None => {
                reads::write_jsonl(&mut self.buf, r)?;
                self.buf.len()
            }
        };
        if buffered >= SINK_BUFFER {
            self.flush()?;
        }
        Ok(())
    }

    pub(super) fn flush(&mut self) -> io::Result<()> {
        if let Some(w) = &mut self.csv {
            self.buf = w.take();
        }
        if let Some(out) = &mut self.out {
            out.write_all(&self.buf)?;
            out.flush()?;
        }
        self.buf.clear();
        Ok(())
    }
}
