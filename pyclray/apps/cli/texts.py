"""The command line's exit statuses and the text that explains them."""

EXIT_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130
EXIT_STATUS_HELP = (
    "Exit status: 0 done; 1 a check outside its tolerance (or an unexpected error); 2 bad input (one "
    "line naming the file, table and key, or the option) or an output that cannot be written (a "
    "missing or read-only folder, a full disk, a path that is a folder); 130 interrupted. On 2 and "
    "130 no output file is replaced: the files of one command are replaced together or not at all."
)
