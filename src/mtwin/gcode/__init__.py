"""G-code front end: lexer, interpreter, writer and geometry check."""
