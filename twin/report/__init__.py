"""The HTML report of a check, diff or replay (plots of each diverging field against its
allowance, the paths from above, both runs' events, the pictures at the onset) and the Markdown
job summary for CI."""
