//! Items binned on a row-major grid of cells by the cells their boxes cover, with a counting
//! sort: each cell's items are one run of a single array, in item order, and so are the items of
//! consecutive cells of a row. Used by the searches that ask "what lies near here?" of polygon
//! edges ([`crate::validation`]), long-edged triangles (`trust`) and keep-out disks
//! ([`crate::polylabel`]).

/// Cell `c`'s items are `items[start[c]..start[c + 1]]`.
#[derive(Debug, Default)]
pub(crate) struct Bins {
    start: Vec<u32>,
    items: Vec<u32>,
}

impl Bins {
    /// Item `i` in every cell of `spans[i]`, `[first column, last column, first row, last row]`
    /// of a grid `columns` wide and `rows` high (each span within it).
    pub(crate) fn new(spans: &[[usize; 4]], columns: usize, rows: usize) -> Self {
        let mut start = vec![0u32; columns * rows + 1];
        for &[x0, x1, y0, y1] in spans {
            for y in y0..=y1 {
                for c in &mut start[y * columns + x0 + 1..=y * columns + x1 + 1] {
                    *c += 1;
                }
            }
        }
        for i in 1..start.len() {
            start[i] += start[i - 1];
        }
        let mut next = start.clone();
        let mut items = vec![0; start[columns * rows] as usize];
        for (i, &[x0, x1, y0, y1]) in spans.iter().enumerate() {
            for y in y0..=y1 {
                for n in &mut next[y * columns + x0..=y * columns + x1] {
                    items[*n as usize] = i as u32;
                    *n += 1;
                }
            }
        }
        Self { start, items }
    }

    /// The items of cells `first..=last` (a run of one row's cells), each once per cell it is in.
    pub(crate) fn run(&self, first: usize, last: usize) -> &[u32] {
        &self.items[self.start[first] as usize..self.start[last + 1] as usize]
    }
}
