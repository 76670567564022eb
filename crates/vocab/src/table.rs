//! CSV as every file of the project reads and writes it, through the `csv` crate: RFC 4180
//! quoting, LF or CRLF line ends, a UTF-8 byte-order mark (Excel's default) ignored, cells
//! trimmed, blank lines and lines starting with `#` skipped. A file is told apart from JSON
//! Lines by its first meaningful line ([`is_json_lines`]).

use std::io;

/// The byte-order mark a spreadsheet puts at the start of a UTF-8 file.
const BOM: char = '\u{feff}';

/// A CSV file that could not be read: the 1-based line and the reason.
#[derive(Debug, thiserror::Error)]
pub enum CsvError {
    /// The input could not be read.
    #[error("{0}")]
    Io(#[from] io::Error),
    /// A line is not valid CSV (an unterminated quote, a cell that is not UTF-8).
    #[error("line {line}: {reason}")]
    Syntax {
        /// 1-based line number.
        line: u64,
        /// What is wrong.
        reason: String,
    },
}

impl CsvError {
    fn from_csv(e: csv::Error, line: u64) -> CsvError {
        match e.into_kind() {
            csv::ErrorKind::Io(e) => CsvError::Io(e),
            csv::ErrorKind::Utf8 { err, .. } => CsvError::Syntax {
                line,
                reason: format!("not UTF-8: {err}"),
            },
            other => CsvError::Syntax {
                line,
                reason: format!("{other:?}"),
            },
        }
    }
}

/// Whether `text` (a file's start) is JSON Lines: its first line that is not blank, after a
/// byte-order mark, starts with `{`.
pub fn is_json_lines(text: &str) -> bool {
    text.trim_start_matches(BOM)
        .lines()
        .map(str::trim)
        .find(|l| !l.is_empty())
        .is_some_and(|l| l.starts_with('{'))
}

/// `text` without a leading byte-order mark.
pub fn strip_bom(text: &str) -> &str {
    text.strip_prefix(BOM).unwrap_or(text)
}

/// A CSV file's header and rows, read as they are asked for.
pub struct CsvRows<R: io::Read> {
    reader: csv::Reader<LfOnly<R>>,
    header: Vec<String>,
    record: csv::StringRecord,
}

/// One row of a CSV file: its 1-based line and its cells, trimmed.
#[derive(Clone, Debug, PartialEq)]
pub struct CsvRow {
    /// The line the row ends on (its only line, unless a quoted cell spans lines).
    pub line: u64,
    /// The cells in the file's order.
    pub cells: Vec<String>,
}

impl<R: io::Read> CsvRows<R> {
    /// Opens `input` (which may start with a byte-order mark) and reads its header row.
    pub fn new(input: R) -> Result<Self, CsvError> {
        let mut reader = csv::ReaderBuilder::new()
            .has_headers(true)
            .flexible(true)
            .trim(csv::Trim::All)
            .comment(Some(b'#'))
            .from_reader(LfOnly::new(input));
        let header = reader
            .headers()
            .map_err(|e| CsvError::from_csv(e, 1))?
            .iter()
            .map(|c| strip_bom(c).trim().to_string())
            .collect();
        Ok(CsvRows {
            reader,
            header,
            record: csv::StringRecord::new(),
        })
    }

    /// The header's column names, trimmed.
    pub fn header(&self) -> &[String] {
        &self.header
    }

    /// The next row that is not blank; `None` at the end.
    pub fn next_row(&mut self) -> Option<Result<CsvRow, CsvError>> {
        loop {
            let read = self.reader.read_record(&mut self.record);
            // The record's own position counts from where the reader began to look for it,
            // before any blank or comment line; where it ended is exact.
            let end = self.reader.position().byte();
            let line = self.reader.get_mut().line_of(end.saturating_sub(1));
            match read {
                Err(e) => return Some(Err(CsvError::from_csv(e, line))),
                Ok(false) => return None,
                Ok(true) => {}
            }
            if self.record.iter().all(str::is_empty) {
                continue;
            }
            let cells = self.record.iter().map(str::to_string).collect();
            return Some(Ok(CsvRow { line, cells }));
        }
    }
}

impl<R: io::Read> Iterator for CsvRows<R> {
    type Item = Result<CsvRow, CsvError>;

    fn next(&mut self) -> Option<Self::Item> {
        self.next_row()
    }
}

/// Writes rows of CSV into a byte buffer the caller drains: cells quoted where RFC 4180 needs
/// it (a comma, a quote, a line end), rows ended by LF.
pub struct CsvWriter {
    writer: csv::Writer<Vec<u8>>,
}

impl Default for CsvWriter {
    fn default() -> Self {
        CsvWriter::new()
    }
}

impl CsvWriter {
    /// A writer with an empty buffer.
    pub fn new() -> CsvWriter {
        CsvWriter {
            writer: Self::fresh(),
        }
    }

    fn fresh() -> csv::Writer<Vec<u8>> {
        csv::WriterBuilder::new()
            .terminator(csv::Terminator::Any(b'\n'))
            .from_writer(Vec::new())
    }

    /// Appends one row.
    pub fn row<I, T>(&mut self, cells: I) -> io::Result<()>
    where
        I: IntoIterator<Item = T>,
        T: AsRef<[u8]>,
    {
        self.writer.write_record(cells).map_err(into_io)?;
        self.writer.flush()
    }

    /// The bytes written so far and not yet taken.
    pub fn buffered(&self) -> &[u8] {
        self.writer.get_ref()
    }

    /// Takes the bytes written so far, leaving the buffer empty.
    pub fn take(&mut self) -> Vec<u8> {
        // Every row is flushed into the vector as it is written, so nothing is lost here.
        std::mem::replace(&mut self.writer, Self::fresh())
            .into_inner()
            .unwrap_or_default()
    }
}

/// `input` with each CR that ends a line (before an LF) dropped, keeping count of the line
/// ends it passes on: the csv crate's own line numbers skip blank lines, comments and a CRLF
/// header, so a row's line is found from its byte offset here.
struct LfOnly<R> {
    input: io::BufReader<R>,
    /// Bytes passed on so far.
    passed: u64,
    /// Offsets of the LFs passed on and not yet behind an asked-for offset.
    line_ends: std::collections::VecDeque<u64>,
    /// LFs behind the last asked-for offset.
    lines_before: u64,
}

impl<R: io::Read> LfOnly<R> {
    fn new(input: R) -> Self {
        LfOnly {
            input: io::BufReader::new(input),
            passed: 0,
            line_ends: Default::default(),
            lines_before: 0,
        }
    }

    /// The 1-based line of byte `offset`; offsets are asked for in increasing order.
    fn line_of(&mut self, offset: u64) -> u64 {
        while self.line_ends.front().is_some_and(|&e| e < offset) {
            self.line_ends.pop_front();
            self.lines_before += 1;
        }
        self.lines_before + 1
    }
}

impl<R: io::Read> io::Read for LfOnly<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        use io::BufRead;
        let mut out = 0;
        while out < buf.len() {
            let avail = self.input.fill_buf()?;
            let Some(&first) = avail.first() else { break };
            if first == b'\r' {
                self.input.consume(1);
                if self.input.fill_buf()?.first() != Some(&b'\n') {
                    buf[out] = b'\r';
                    out += 1;
                    self.passed += 1;
                }
                continue;
            }
            let run = avail
                .iter()
                .position(|&b| b == b'\r')
                .unwrap_or(avail.len())
                .min(buf.len() - out);
            let whole = run == avail.len();
            buf[out..out + run].copy_from_slice(&avail[..run]);
            self.input.consume(run);
            for (i, &b) in buf[out..out + run].iter().enumerate() {
                if b == b'\n' {
                    self.line_ends.push_back(self.passed + i as u64);
                }
            }
            self.passed += run as u64;
            out += run;
            if whole {
                // The chunk the input had is given; do not wait for more.
                break;
            }
        }
        Ok(out)
    }
}

fn into_io(e: csv::Error) -> io::Error {
    match e.into_kind() {
        csv::ErrorKind::Io(e) => e,
        other => io::Error::other(format!("{other:?}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(text: &str) -> (Vec<String>, Vec<CsvRow>) {
        let mut r = CsvRows::new(text.as_bytes()).expect("a header");
        let rows = r
            .by_ref()
            .collect::<Result<Vec<_>, _>>()
            .expect("valid CSV");
        (r.header().to_vec(), rows)
    }

    #[test]
    fn a_bom_crlf_and_quotes_read_as_plain_cells() {
        let text =
            "\u{feff}name, value\r\n\"dock, door 1\",\"say \"\"hi\"\"\"\r\n\r\n# a note\r\nb,2\r\n";
        let (header, rows) = rows(text);
        assert_eq!(header, ["name", "value"]);
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[0].cells, ["dock, door 1", "say \"hi\""]);
        assert_eq!(rows[0].line, 2);
        let (_, spans) = self::rows("a,b\n\n# note\n\"x\ny\",1\n2,3");
        let lines: Vec<u64> = spans.iter().map(|r| r.line).collect();
        assert_eq!(lines, [5, 6], "{spans:?}");
        assert_eq!(
            (rows[1].line, rows[1].cells.clone()),
            (5, vec!["b".into(), "2".into()])
        );
    }

    #[test]
    fn a_cell_that_is_not_utf8_names_its_line() {
        let mut r = CsvRows::new(&b"a,b\n1,2\n\xff,3\n"[..]).expect("a header");
        assert!(r.next_row().expect("row 1").is_ok());
        let err = r.next_row().expect("row 2").expect_err("not UTF-8");
        assert!(err.to_string().starts_with("line 3:"), "{err}");
    }

    #[test]
    fn written_cells_that_need_quotes_get_them_and_read_back_equal() {
        let mut w = CsvWriter::new();
        w.row(["epc", "reader"]).expect("in memory");
        w.row(["3000", "dock, \"north\"\nline 2"])
            .expect("in memory");
        let bytes = w.take();
        let text = String::from_utf8(bytes).expect("UTF-8");
        assert!(text.contains("\"dock, \"\"north\"\"\nline 2\""), "{text}");
        assert!(w.buffered().is_empty());
        let (_, rows) = rows(&text);
        assert_eq!(rows[0].cells, ["3000", "dock, \"north\"\nline 2"]);
    }

    #[test]
    fn json_lines_are_told_from_csv_after_a_bom_and_blank_lines() {
        assert!(is_json_lines("\u{feff}\n  {\"t_us\": 1}\n"));
        assert!(!is_json_lines("\u{feff}t_us,x\n"));
        assert!(!is_json_lines(""));
    }
}
