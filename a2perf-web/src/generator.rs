//! The seeded website generator (A2Perf's `generate_webpages.py` sampling process, with levels
//! assigned from the recomputed difficulty and a solvability check at generation time).

use a2perf_core::RngStream;

use crate::design::Design;
use crate::primitives::Primitive;
use crate::site::Website;
use crate::vocab::Vocabulary;

/// Limits a website must respect to be playable by an environment of a given size.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Episode step limit (A2Perf: 25).
    pub step_limit: usize,
    /// Elements the observation holds (A2Perf: 250); every page must fit, hidden ones included.
    pub max_elements: usize,
    /// Profile fields the observation holds besides `_dummy` (A2Perf: 25 − 1).
    pub max_fields: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            step_limit: 25,
            max_elements: 250,
            max_fields: 24,
        }
    }
}

/// Why a design cannot be completed within the limits.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Unsolvable {
    /// Filling every field, changing pages and submitting takes more steps than allowed.
    TooManySteps {
        /// Steps an optimal agent needs.
        needed: usize,
    },
    /// A page has more elements than the observation holds.
    TooManyElements {
        /// The page.
        page: usize,
        /// Its element count.
        elements: usize,
    },
    /// More profile fields than the observation holds.
    TooManyFields {
        /// Field count.
        fields: usize,
    },
}

/// Number of symbols A2Perf's sampler draws from: `#none#`, the 40 primitives, `#next_page#`.
pub const NUM_SYMBOLS: usize = 42;
/// Safety cap on draws per website (the original had none; the expected length is 41 draws).
pub const MAX_DRAWS: usize = 2000;

/// Draws one design the way `generate_webpages.py` does: symbols uniformly from the 42 until
/// `#none#` (stop); `#next_page#` starts a new page. Trailing empty pages are dropped (they vanish
/// in `design_environment`).
///
/// ```
/// use a2perf_core::RngStream;
/// let d = a2perf_web::sample_design(&mut RngStream::new(1, "doc"));
/// assert!(d.pages.iter().all(|p| p.len() < 2000));
/// ```
pub fn sample_design(rng: &mut RngStream) -> Design {
    let mut pages: Vec<Vec<Primitive>> = vec![Vec::new()];
    for _ in 0..MAX_DRAWS {
        let s = rng.index(NUM_SYMBOLS);
        if s == 0 {
            break;
        }
        if s == NUM_SYMBOLS - 1 {
            pages.push(Vec::new());
        } else if let Some(last) = pages.last_mut() {
            last.push(Primitive::ALL[s - 1]);
        }
    }
    while pages.len() > 1 && pages.last().is_some_and(Vec::is_empty) {
        pages.pop();
    }
    Design { pages }
}

/// Candidate `index` of the generator stream of `seed` (independent of other candidates).
pub fn candidate(seed: u64, index: u64) -> Design {
    sample_design(&mut RngStream::new(seed, "web-generator").derive_index(index))
}

/// Checks that an optimal agent can finish `design` within `limits`.
pub fn check_solvable(design: &Design, limits: &Limits) -> Result<(), Unsolvable> {
    let fields = design.unique_active().len();
    if fields > limits.max_fields {
        return Err(Unsolvable::TooManyFields { fields });
    }
    let needed = design.oracle_steps();
    if needed > limits.step_limit {
        return Err(Unsolvable::TooManySteps { needed });
    }
    // Element counts do not depend on the episode's random content.
    let site = Website::build(
        design,
        &mut RngStream::new(0, "size-check"),
        Vocabulary::standard(),
    );
    for (page, elements) in site.page_sizes().into_iter().enumerate() {
        if elements > limits.max_elements {
            return Err(Unsolvable::TooManyElements { page, elements });
        }
    }
    Ok(())
}

/// A generated website with its provenance.
#[derive(Clone, Debug, PartialEq)]
pub struct Generated {
    /// Candidate index in the generator stream.
    pub index: u64,
    /// The design.
    pub design: Design,
    /// Its difficulty.
    pub difficulty: f64,
}

/// The first `count` designs of `level` (1–3) in the generator stream of `seed` that are solvable
/// within `limits`, sorted by candidate index.
///
/// ```
/// use a2perf_web::{generate, Limits};
/// let sites = generate(1, 0, 3, &Limits::default());
/// assert_eq!(sites.len(), 3);
/// assert!(sites.iter().all(|g| g.design.level() == Some(1)));
/// ```
pub fn generate(level: u8, seed: u64, count: usize, limits: &Limits) -> Vec<Generated> {
    let mut out = Vec::with_capacity(count);
    let mut index = 0u64;
    while out.len() < count {
        let design = candidate(seed, index);
        if design.level() == Some(level) && check_solvable(&design, limits).is_ok() {
            out.push(Generated {
                index,
                difficulty: design.difficulty(),
                design,
            });
        }
        index += 1;
    }
    out
}

/// Summary of a set of designs (e.g. A2Perf's shipped files): how many can be solved here, and
/// their levels recomputed from the difficulty formula.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DesignReport {
    /// Designs read.
    pub total: usize,
    /// Solvable within the limits (the `cc` bug is fixed here, so only budgets matter).
    pub solvable: usize,
    /// Designs containing `cc` (unsolvable in the original).
    pub with_cc: usize,
    /// Needing more steps than the limit.
    pub too_many_steps: usize,
    /// With a page larger than the observation.
    pub too_many_elements: usize,
    /// Solvable designs per recomputed level (index 0: too easy for any level, 1–3: levels).
    pub solvable_by_level: [usize; 4],
    /// Designs that were solvable in the original (no `cc`, within the step limit).
    pub original_solvable: usize,
}

/// Classifies `designs` against `limits`.
pub fn report(designs: &[Design], limits: &Limits) -> DesignReport {
    let mut r = DesignReport {
        total: designs.len(),
        ..Default::default()
    };
    let cc = Primitive::from_name("cc");
    for d in designs {
        let has_cc = d.pages.iter().flatten().any(|p| Some(*p) == cc);
        r.with_cc += usize::from(has_cc);
        match check_solvable(d, limits) {
            Ok(()) => {
                r.solvable += 1;
                r.solvable_by_level[usize::from(d.level().unwrap_or(0))] += 1;
                r.original_solvable += usize::from(!has_cc);
            }
            Err(Unsolvable::TooManySteps { .. }) => r.too_many_steps += 1,
            Err(Unsolvable::TooManyElements { .. }) => r.too_many_elements += 1,
            Err(Unsolvable::TooManyFields { .. }) => r.too_many_steps += 1,
        }
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn candidates_are_deterministic_and_independent() {
        assert_eq!(candidate(7, 3), candidate(7, 3));
        assert_ne!(candidate(7, 3), candidate(8, 3));
        let a = generate(2, 5, 4, &Limits::default());
        let b = generate(2, 5, 4, &Limits::default());
        assert_eq!(a, b);
        assert!(a.windows(2).all(|w| w[0].index < w[1].index));
    }
}
