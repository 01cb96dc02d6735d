//! Words for numbers, so that pages and messages read as people write: "1 estimate",
//! "2 estimates".

/// `n` and its noun in the number `n` asks for.
pub fn counted(n: impl std::fmt::Display, noun: &str) -> String {
    let n = n.to_string();
    if n == "1" {
        return format!("1 {noun}");
    }
    let consonant_y = noun.strip_suffix('y').filter(|stem| {
        stem.chars()
            .last()
            .is_some_and(|c| !"aeiou".contains(c.to_ascii_lowercase()))
    });
    let plural = match consonant_y {
        Some(stem) => format!("{stem}ies"),
        None if ["s", "x", "ch", "sh"].iter().any(|e| noun.ends_with(e)) => format!("{noun}es"),
        None => format!("{noun}s"),
    };
    format!("{n} {plural}")
}

#[cfg(test)]
mod tests {
    use super::counted;

    #[test]
    fn counts_take_the_noun_they_need() {
        assert_eq!(counted(1, "estimate"), "1 estimate");
        assert_eq!(counted(0, "estimate"), "0 estimates");
        assert_eq!(counted(2_i64, "estimate"), "2 estimates");
        assert_eq!(counted(1_usize, "entry"), "1 entry");
        assert_eq!(counted(3, "entry"), "3 entries");
        assert_eq!(counted(3, "day"), "3 days");
        assert_eq!(counted(2, "match"), "2 matches");
        assert_eq!(counted(11, "instance"), "11 instances");
    }
}
