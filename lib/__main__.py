from mjzoo.cli import main

main()
