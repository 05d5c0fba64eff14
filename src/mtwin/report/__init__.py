"""Human-facing output: plots (matplotlib, SVG) and, later, the HTML report."""
