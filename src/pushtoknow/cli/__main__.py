from pushtoknow.cli.main import main

main()
