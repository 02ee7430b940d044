from mjzoo.harness.cli import main

main()
