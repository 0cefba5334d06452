// hybgen command-line entry point (filled in by the CLI stage).
int main() { return 0; }
