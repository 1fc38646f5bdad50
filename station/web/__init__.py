"""The fleet web view (`station web`): read-only HTML pages over a catalog. docs/web.md."""
