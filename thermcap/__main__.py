from thermcap.cli import main

main()
