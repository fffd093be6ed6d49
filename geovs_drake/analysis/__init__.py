"""Analysis: navigation-function studies, linearisation, Monte-Carlo."""
