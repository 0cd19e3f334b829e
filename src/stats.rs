//! Statistical tests: chi-square goodness of fit and the special functions it needs.
