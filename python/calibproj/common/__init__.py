"""What every stage uses: option tables from the core's declarations, progress, interruption."""
